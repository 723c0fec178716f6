"""Look at what the host sees, or watch a trained host drive.

Still picture (the human-like host, the NPC behaviour under the NPC safety layer): after `steps`
decisions (default 40), one PNG of the front camera, the Hyper-Grid Matrix and a top-down view:

    python -m hgm_repro.show scenario=3 seed=0 [steps=40] [out=show/] [env=0] [hgm=paper|enriched]
                             [camera=front|birdseye] [height=84] [width=84]

Watching a trained agent: an animation (MP4 when imageio-ffmpeg is installed, else GIF) of the learned
host driving one episode of `scenario` (traffic drawn from `seed`), every frame showing the network's
inputs (camera, HGM), its Q-values and the chosen action beside the top-down view:

    python -m hgm_repro.show run_id=<training run id> scenario=3 seed=0 [tracking_uri=sqlite:///...]
    python -m hgm_repro.show checkpoint=checkpoints/<train_key>/final.pt scenario=3 seed=0 [model=proposed]
                             [steps=N] [format=auto|gif|mp4] [device=cpu] [out=show/]

`run_id` is a training run in the MLflow store (`./mlflow.db` unless `tracking_uri` says otherwise; an
evaluation run stands for its training); the network, observation and simulator settings come from it.
With `checkpoint`, they come from the checkpoint; `model` (default: the checkpoint's) must match it.
`steps` limits the decisions filmed (default: one whole episode); the animation has steps + 1 frames.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

USAGE = __doc__

DEFAULTS: dict[str, str] = {"scenario": "train", "seed": "0", "steps": "", "out": "show", "env": "0",
                            "hgm": "paper", "camera": "front", "height": "84", "width": "84",
                            "run_id": "", "checkpoint": "", "model": "", "tracking_uri": "", "format": "auto",
                            "device": "cpu"}
STILL_ONLY = ("env", "hgm", "camera", "height", "width")
WATCH_ONLY = ("run_id", "checkpoint", "model", "tracking_uri", "format", "device")
STILL_STEPS = 40


class WatchError(SystemExit):
    """What stops a watch, in one line (no traceback): a missing run, a checkpoint of another model."""

    def __init__(self, message: str) -> None:
        super().__init__(f"hgm_repro.show: {message}")


def parse_args(argv: list[str]) -> dict[str, str]:
    """key=value pairs over DEFAULTS; unknown keys fail with the list of allowed ones."""
    args = dict(DEFAULTS)
    given = set()
    for item in argv:
        if "=" not in item:
            raise SystemExit(f"expected key=value, got {item!r}\n{USAGE}")
        key, value = item.split("=", 1)
        if key not in DEFAULTS:
            raise SystemExit(f"unknown argument {key!r}; allowed: {sorted(DEFAULTS)}")
        args[key] = value
        given.add(key)
    watching = bool(args["run_id"] or args["checkpoint"])
    if args["run_id"] and args["checkpoint"]:
        raise SystemExit("give run_id= or checkpoint=, not both")
    wrong = sorted(given & set(STILL_ONLY if watching else WATCH_ONLY[2:]))
    if wrong:
        mode = "watching (run_id= or checkpoint=)" if watching else "a still picture (no run_id= or checkpoint=)"
        raise SystemExit(f"{', '.join(wrong)} do(es) not apply to {mode}")
    return args


def main(argv: list[str] | None = None) -> Path:
    argv = sys.argv[1:] if argv is None else argv
    if any(a in ("-h", "--help", "help") for a in argv):
        print(USAGE)
        raise SystemExit(0)
    args = parse_args(argv)
    if args["run_id"] or args["checkpoint"]:
        return watch(args)
    return still(args)


def still(args: dict[str, str]) -> Path:
    """The still picture of the human-like host's view after `steps` decisions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hgm_repro.contracts.config_files import observation_config, scenario_config, simulator_config
    from hgm_repro.envs.render import hgm_colour_limit, render_top_down
    from hgm_repro.observations import ObservationBuilder, decode_hgm, hyper_grid_matrix
    from hgm_repro.simulator import HOST, HighwaySimulator

    env, steps = int(args["env"]), int(args["steps"] or STILL_STEPS)
    obs_cfg = observation_config({"camera": args["camera"], "hgm": args["hgm"], "coordinates": False},
                                 height=int(args["height"]), width=int(args["width"]))
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
    lim = hgm_colour_limit(sim_cfg)
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


def watch(args: dict[str, str]) -> Path:
    """An animation of a trained host driving one episode; the path it was written to."""
    from omegaconf import open_dict

    from hgm_repro.contracts.checkpoint import CheckpointMismatchError
    from hgm_repro.contracts.errors import ConfigError
    from hgm_repro.contracts.schema import check_config
    from hgm_repro.evaluation.media import record_gif

    scenario = _scenario_node(args["scenario"])  # the arguments first: nothing is fetched for a bad one
    fmt = args["format"]
    if fmt == "auto":
        fmt = "mp4" if importlib.util.find_spec("imageio_ffmpeg") is not None else "gif"
    if fmt not in ("gif", "mp4"):
        raise WatchError(f"format={fmt!r}: use gif, mp4 or auto")
    if args["run_id"]:
        cfg, checkpoint = _from_run(args["run_id"], args["tracking_uri"])
    else:
        checkpoint = Path(args["checkpoint"])
        cfg = _from_checkpoint(checkpoint, args["model"])
    with open_dict(cfg):
        cfg.scenario = scenario
        cfg.device = args["device"]
    out = Path(args["out"]) / (f"watch_{cfg.model.name}_seed{cfg.seed}_scenario{args['scenario']}"
                               f"_traffic{args['seed']}.{fmt}")
    try:
        job = check_config(cfg)
    except ConfigError as error:
        raise WatchError(str(error)) from None
    try:
        metrics = record_gif(job, checkpoint, out, seed=int(args["seed"]), panels=True,
                             max_decisions=int(args["steps"]) if args["steps"] else None)
    except CheckpointMismatchError as error:
        raise WatchError(f"{error}\nTo watch this checkpoint, leave model= out (it names its own model).") from None
    print(f"{out}: {int(metrics.get('decisions', 0))} decisions, {metrics.get('avg_speed_kmh', 0):.1f} km/h, "
          f"return {metrics.get('episode_return', 0):.2f}, collisions {int(metrics.get('collisions', 0))}")
    return out


def _scenario_node(name: str) -> Any:
    from omegaconf import OmegaConf

    from hgm_repro.contracts.conf_dir import CONF_DIR

    path = CONF_DIR / "scenario" / f"{name}.yaml"
    if not path.is_file():
        names = sorted(p.stem for p in (CONF_DIR / "scenario").glob("*.yaml"))
        raise WatchError(f"no scenario {name!r}; choose one of {names}")
    return OmegaConf.load(path)


def _from_run(run_id: str, tracking_uri: str) -> tuple[Any, Path]:
    """The config and final checkpoint of a training run (an evaluation run stands for its training)."""
    import tempfile

    from omegaconf import OmegaConf

    from hgm_repro.app.store import Tracker, resolve_location
    from hgm_repro.app.trainings import local_checkpoint

    location = resolve_location({"uri": tracking_uri or None}, Path.cwd(), create=False)
    db = location.tracking_uri.removeprefix("sqlite:///")
    if location.tracking_uri.startswith("sqlite:///") and not Path(db).is_file():
        raise WatchError(f"no MLflow store at {db}: start from the directory the jobs ran in, or give tracking_uri=")
    tracker = Tracker(location, "hgm_repro")
    run = tracker.get_run(run_id)
    if run is None:
        raise WatchError(f"no run {run_id!r} in {location.tracking_uri}")
    if run.data.tags.get("stage") == "eval":
        if not run.data.tags.get("train_run_id"):
            raise WatchError(f"run {run_id} evaluated a non-learning host ({run.data.tags.get('model')}): "
                             "there is no trained network to watch")
        run = tracker.get_run(run.data.tags["train_run_id"])
        if run is None:
            raise WatchError(f"the training run of evaluation run {run_id} is gone from {location.tracking_uri}")
    if run.data.tags.get("stage") != "train":
        raise WatchError(f"run {run_id} is not a training run (stage={run.data.tags.get('stage')!r})")
    scratch = Path(tempfile.mkdtemp(prefix="hgm_watch_"))
    config = tracker.download(run.info.run_id, "config.yaml", scratch)
    checkpoint = local_checkpoint(tracker, run, scratch)
    if checkpoint is None:
        raise WatchError(f"training run {run.info.run_id} has no checkpoint left, on disk or in the store")
    return OmegaConf.load(config), checkpoint


def _from_checkpoint(path: Path, model: str) -> Any:
    """The job config of `model` (default: the checkpoint's own) with the checkpoint's recorded
    observation and simulator settings; the network is checked against it when it loads."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf, open_dict

    from hgm_repro.contracts.checkpoint import CheckpointMismatchError, load_checkpoint
    from hgm_repro.contracts.conf_dir import CONF_DIR

    if not path.is_file():
        raise WatchError(f"no checkpoint at {path}")
    try:
        state = load_checkpoint(path)
    except CheckpointMismatchError as error:
        raise WatchError(str(error)) from None
    recorded: dict[str, Any] = {}
    for key, value in state.get("training_config", {}).items():
        node = recorded
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    name = model or state.get("model") or recorded.get("model", {}).get("name")
    if not (CONF_DIR / "model" / f"{name}.yaml").is_file():
        raise WatchError(f"no model {name!r} in {CONF_DIR / 'model'}")
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=[f"model={name}"])
    with open_dict(cfg):
        for part in ("observation", "simulator"):
            if part in recorded:
                cfg[part] = OmegaConf.merge(cfg[part], recorded[part])
        cfg.seed = int(recorded.get("seed", cfg.seed))
    return cfg


if __name__ == "__main__":
    torch.set_grad_enabled(False)
    main()
