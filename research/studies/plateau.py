"""The plateau diagnosis: what crashes a learned host, and what its network can perceive.

    python research/studies/plateau.py --checkpoint PATH [--overrides experiment=quick ...] [--out docs/study]

Drives the learned host (greedy, from a checkpoint) and IDM + MOBIL inside the host's own limits
(no safety layer) through the same training traffic, classifies every collision and dangerous
action (research/studies/incidents.py), and measures what the quick preset's observations show of the
two things a driver needs most: the gap and closing speed to the vehicle ahead (camera), and the
host's own speed (the HGM's host cells; the camera does not show it). Writes CSV files and PNG
figures to --out.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
import torch  # noqa: E402
from hydra import compose, initialize_config_dir  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from incidents import COLLISION_KINDS, DANGER_KINDS, drive_and_classify  # noqa: E402

from baselines.drivers import IdmMobilDriver  # noqa: E402
from hgm_repro.contracts.schema import JobConfig, check_config  # noqa: E402
from hgm_repro.models.builders import make_network  # noqa: E402
from hgm_repro.observations import ObservationBuilder  # noqa: E402
from hgm_repro.simulator import HOST, HighwaySimulator  # noqa: E402
from hgm_repro.simulator.driver import attach  # noqa: E402

CONF = Path(__file__).resolve().parents[2] / "conf"


def compose_job(overrides: list[str]) -> JobConfig:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return check_config(compose("config", overrides=overrides))


def make_sim(job: JobConfig, n_envs: int, seed: int) -> HighwaySimulator:
    return HighwaySimulator(job.simulator, job.train_scenario, n_envs=n_envs, seed=seed)


def learned_host(job: JobConfig, checkpoint: Path, n_envs: int, decisions: int, seed: int):
    sim = make_sim(job, n_envs, seed)
    builder = ObservationBuilder(sim, job.observation)
    net = make_network(job)
    # The weights only: the caller passes the overrides the checkpoint was trained with (a checkpoint
    # from before a config field existed would fail the strict config comparison).
    net.load_state_dict(torch.load(checkpoint, map_location="cpu", weights_only=False)["network"])
    net.eval()
    obs = {"now": builder.reset()}
    host_speeds: list[torch.Tensor] = []

    @torch.no_grad()
    def act() -> torch.Tensor:
        host_speeds.append(sim.state.speed[:, HOST].clone())
        return net(*(obs["now"][k] for k in net.in_keys)).argmax(-1)

    def after_step(done: torch.Tensor) -> None:
        obs["now"] = builder.step()
        if bool(done.any()):
            obs["now"] = builder.reset(done)

    table, rates = drive_and_classify(sim, act, decisions, after_step)
    return table, rates, torch.cat(host_speeds)


def rule_host(job: JobConfig, n_envs: int, decisions: int, seed: int):
    sim = make_sim(job, n_envs, seed)
    driver = attach(IdmMobilDriver(safety_layer=False), sim)  # inside the host's own Table 1 limits
    sim.reset()
    return drive_and_classify(sim, lambda: driver.act(sim), decisions)


def camera_resolution(job: JobConfig) -> pd.DataFrame:
    """Rows a car ahead covers in the front camera, and how many rows it grows by in one decision
    while closing at 2 m/s, against the gap; at the preset's image size and at the paper's 84."""
    obs = job.observation
    rows = []
    for side in sorted({obs.width, 84}):
        f = (side / 2) / math.tan(math.radians(obs.camera_fov_deg) / 2)
        for gap in (5.0, 7.5, 10.0, 15.0, 20.0, 30.0, 40.0):
            tall = f * obs.vehicle_height / gap
            grow = f * obs.vehicle_height * (1 / (gap - 1.0) - 1 / gap)
            wide = f * 1.8 / gap
            rows.append({"image_side": side, "gap_m": gap, "rows_tall": tall, "columns_wide": wide,
                         "rows_grown_per_decision_at_2mps": grow})
    return pd.DataFrame(rows)


def hgm_host_contrast(speeds_ms: torch.Tensor, v_min: float, v_max: float) -> pd.DataFrame:
    """The host cell's HGM value against speed: uint8 levels between the host and an empty cell."""
    mid = (v_max + v_min) / 2
    value = (speeds_ms - mid) / mid
    levels = (value * 127.5).abs()
    return pd.DataFrame({"speed_kmh": (speeds_ms * 3.6).numpy(), "hgm_value": value.numpy(),
                         "levels_from_empty": levels.numpy()})


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", type=Path, required=True, help="final.pt of a learned host")
    p.add_argument("--overrides", nargs="*", default=["experiment=quick"], help="Hydra overrides it was trained with")
    p.add_argument("--decisions", type=int, default=960, help="decisions per env (240 = one episode)")
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--seed", type=int, default=900_001, help="traffic seed (no test or training uses it)")
    p.add_argument("--out", type=Path, default=Path("research/study"))
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    job = compose_job(a.overrides)
    a.out.mkdir(parents=True, exist_ok=True)

    learned_table, learned_rates, speeds = learned_host(job, a.checkpoint, a.envs, a.decisions, a.seed)
    rule_table, rule_rates = rule_host(job, a.envs, a.decisions, a.seed)
    rates = pd.DataFrame([{"host": "learned (proposed)", **learned_rates},
                          {"host": "IDM + MOBIL, host limits", **rule_rates}])
    rates.to_csv(a.out / "plateau_incident_rates.csv", index=False)
    pd.concat([learned_table.assign(host="learned"), rule_table.assign(host="idm_mobil")]).to_csv(
        a.out / "plateau_collisions.csv", index=False)
    cam = camera_resolution(job)
    cam.to_csv(a.out / "plateau_camera_resolution.csv", index=False)
    sim_cfg = job.simulator
    contrast = hgm_host_contrast(speeds, sim_cfg.v_min, sim_cfg.v_max)
    contrast.describe().to_csv(a.out / "plateau_hgm_host_contrast.csv")

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    kinds = [f"collision/{k}" for k in COLLISION_KINDS]
    rates.set_index("host")[kinds].rename(columns=lambda c: c.split("/")[1]).T.plot.bar(ax=axes[0], rot=20)
    axes[0].set_ylabel("per episode (240 decisions)")
    axes[0].set_title("Host collisions by kind")
    dkinds = [f"dangerous/{k}" for k in DANGER_KINDS]
    rates.set_index("host")[dkinds].rename(columns=lambda c: c.split("/")[1]).T.plot.bar(ax=axes[1], rot=0)
    axes[1].set_title("Dangerous actions by kind")
    axes[1].set_ylabel("per episode")
    for side, grp in cam.groupby("image_side"):
        axes[2].plot(grp["gap_m"], grp["rows_tall"], marker="o", label=f"{side} px: rows a car covers")
        axes[2].plot(grp["gap_m"], grp["rows_grown_per_decision_at_2mps"], ls="--", marker=".",
                     label=f"{side} px: growth per decision at 2 m/s closing")
    axes[2].axhline(1.0, color="grey", lw=0.8)
    axes[2].set_yscale("log")
    axes[2].set_xlabel("gap to the car ahead (m)")
    axes[2].set_ylabel("image rows")
    axes[2].set_title("What the camera shows of the car ahead")
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(a.out / "plateau_diagnosis.png", dpi=110)

    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.hist(contrast["speed_kmh"], bins=40, color="tab:blue")
    ax.set_xlabel("learned host speed (km/h)")
    ax.set_ylabel("decisions")
    ax2 = ax.twinx()
    v = torch.linspace(sim_cfg.v_min, sim_cfg.v_max, 81)
    ax2.plot(v * 3.6, hgm_host_contrast(v, sim_cfg.v_min, sim_cfg.v_max)["levels_from_empty"], color="tab:red")
    ax2.set_ylabel("host cell: uint8 levels from an empty cell", color="tab:red")
    ax.set_title("The HGM shows the host's speed weakly near 60 km/h")
    fig.tight_layout()
    fig.savefig(a.out / "plateau_hgm_host_speed.png", dpi=110)

    summary = {"learned": learned_rates, "idm_mobil_host_limits": rule_rates,
               "learned_share_of_decisions_within_3kmh_of_60": float(((speeds * 3.6 - 60).abs() < 3).float().mean()),
               "collision_details": learned_table.groupby("kind")[["host_speed_kmh", "partner_speed_kmh", "gap_m"]]
               .mean().round(2).to_dict(orient="index"),
               "host_into_leader_at_v_min": float(learned_table.query("kind == 'host_into_leader'")["host_at_v_min"]
                                                  .mean()) if len(learned_table) else float("nan"),
               "last_action_in_crashes": learned_table["host_action"].value_counts().to_dict(),
               "partner_seen_by": learned_table.assign(
                   sensors=learned_table["partner_connected"].map({True: "HGM", False: ""}).str.cat(
                       learned_table["partner_in_camera"].map({True: "+camera", False: ""}))
                   .replace({"": "neither", "+camera": "camera only", "HGM+camera": "HGM and camera"}))
               .groupby(["kind", "sensors"]).size().to_dict() if len(learned_table) else {}}
    summary["partner_seen_by"] = {f"{k[0]}: {k[1]}": int(v) for k, v in summary["partner_seen_by"].items()}
    (a.out / "plateau_summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
