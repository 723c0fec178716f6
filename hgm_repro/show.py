"""Look at what the host sees: front camera, Hyper-Grid Matrix and a top-down view at one moment.

    python -m hgm_repro.show scenario=3 seed=0 [steps=40] [out=show/] [env=0] [hgm=paper|enriched]
                             [camera=front|birdseye] [height=84] [width=84]

Runs the simulator for `steps` decisions with the human-like host (the NPC behaviour under the
NPC safety layer), then writes one PNG into `out`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

USAGE = __doc__

DEFAULTS: dict[str, str] = {"scenario": "train", "seed": "0", "steps": "40", "out": "show", "env": "0",
                            "hgm": "paper", "camera": "front", "height": "84", "width": "84"}


def parse_args(argv: list[str]) -> dict[str, str]:
    """key=value pairs over DEFAULTS; unknown keys fail with the list of allowed ones."""
    args = dict(DEFAULTS)
    for item in argv:
        if "=" not in item:
            raise SystemExit(f"expected key=value, got {item!r}\n{USAGE}")
        key, value = item.split("=", 1)
        if key not in DEFAULTS:
            raise SystemExit(f"unknown argument {key!r}; allowed: {sorted(DEFAULTS)}")
        args[key] = value
    return args


def main(argv: list[str] | None = None) -> Path:
    argv = sys.argv[1:] if argv is None else argv
    if any(a in ("-h", "--help", "help") for a in argv):
        print(USAGE)
        raise SystemExit(0)
    args = parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from omegaconf import OmegaConf

    from hgm_repro import CONF_DIR
    from hgm_repro.envs.render import render_top_down
    from hgm_repro.observations import ObservationBuilder, ObservationConfig, decode_hgm, hyper_grid_matrix
    from hgm_repro.simulator import HOST, HighwaySimulator
    from hgm_repro.simulator.loading import scenario_config, simulator_config

    env, steps = int(args["env"]), int(args["steps"])
    root = OmegaConf.load(CONF_DIR / "config.yaml")
    obs_node = {**OmegaConf.to_container(root.observation), "height": int(args["height"]),
                "width": int(args["width"])}
    obs_cfg = ObservationConfig.from_config(obs_node, {"camera": args["camera"], "hgm": args["hgm"]})
    sim_cfg = simulator_config(host_safety_layer=True)  # the host drives by the NPC rule, under its safety layer
    sim = HighwaySimulator(sim_cfg, scenario_config(args["scenario"], sim_cfg), n_envs=env + 1,
                           seed=int(args["seed"]))
    for _ in range(steps):
        sim.step(sim.npc_actions(sim.state)[:, HOST])
    frame = ObservationBuilder(sim, obs_cfg).frame()
    camera = frame["camera"][env].permute(1, 2, 0).cpu().numpy()
    hgm = decode_hgm(frame["hgm"][env, 0]).cpu().numpy()
    top = render_top_down(sim, env_index=env)

    s = sim.state
    road = sim_cfg.lanes * sim_cfg.lane_width
    d = obs_cfg.v2x_range
    # The enriched channels outline every vehicle in the grid: a vehicle at the mid speed writes 0,
    # the colour of an empty cell, in the paper's variant.
    enriched = decode_hgm(hyper_grid_matrix(sim, height=obs_cfg.height, width=obs_cfg.width, v2x_range=d,
                                            variant="enriched", encoded=True)[env]).cpu().numpy()
    top_wide = top.shape[1] > 1.5 * top.shape[0]
    fig = plt.figure(figsize=(12, 10 if top_wide else 5.5))
    grid = fig.add_gridspec(2 if top_wide else 1, 2 if top_wide else 3,
                            height_ratios=[1.6, 1] if top_wide else None)
    ax_cam, ax_hgm = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1])
    ax_top = fig.add_subplot(grid[1, :] if top_wide else grid[0, 2])
    ax_cam.imshow(camera, interpolation="nearest")
    ax_cam.set_title(f"{args['camera']} camera, what the network sees ({obs_cfg.height}x{obs_cfg.width})")
    ax_cam.set_xlabel("column (px)")
    ax_cam.set_ylabel("row (px)")
    # Values of vehicles within [v_min, v_max] lie in +-(v_max - v_mid) / v_mid; scale the colours to that.
    v_mid = (sim_cfg.v_max + sim_cfg.v_min) / 2
    lim = (sim_cfg.v_max - v_mid) / v_mid
    extent = (0, road, -d, d)
    im = ax_hgm.imshow(hgm, cmap="RdBu_r", vmin=-lim, vmax=lim, extent=extent, aspect="auto",
                       interpolation="nearest")
    occupied, host_cells = enriched[1] > 0, enriched[2] > 0
    xs = np.linspace(0, road, obs_cfg.width + 1)
    ys = np.linspace(d, -d, obs_cfg.height + 1)
    ax_hgm.contour((xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2, occupied.astype(float), levels=[0.5],
                   colors="k", linewidths=0.6)
    ax_hgm.contour((xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2, host_cells.astype(float), levels=[0.5],
                   colors="red", linewidths=1.2)
    for k in range(1, sim_cfg.lanes):
        ax_hgm.axvline(k * sim_cfg.lane_width, color="0.75", lw=0.5, ls="--")
    ax_hgm.set_title(f"HGM ({args['hgm']}); outlines: connected vehicles, host in red")
    ax_hgm.set_xlabel("lateral position from the left road edge (m)")
    ax_hgm.set_ylabel("longitudinal offset from the host (m, + ahead)")
    fig.colorbar(im, ax=ax_hgm, fraction=0.06, label="cell value (v - v_mid) / v_mid")
    ax_top.imshow(top, interpolation="nearest")
    ax_top.set_title("top-down view")
    ax_top.axis("off")
    speed_kmh = float(s.speed[env, HOST]) * 3.6
    n_conn = int((sim.connected_by_type[s.vtype[env]] & s.active[env]).sum()) - 1
    fig.suptitle(f"scenario {args['scenario']}, seed {args['seed']}, env {env}, after {steps} decisions: "
                 f"host {speed_kmh:.0f} km/h in lane {int(s.target_lane[env, HOST])}; "
                 f"{n_conn} connected vehicles in the world")
    fig.tight_layout()
    out_dir = Path(args["out"])
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"show_scenario{args['scenario']}_seed{args['seed']}_step{steps}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(path)
    return path


if __name__ == "__main__":
    torch.set_grad_enabled(False)
    main()
