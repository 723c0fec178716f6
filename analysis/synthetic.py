"""Synthetic results with known effects: for tests of the analysis and for trying the report.

`synthetic_frames` makes the tables `load_store` returns (eval means per seed, training curves,
episodes) from a `SyntheticSpec`; `write_store` logs them to a real MLflow store in the same
layout the training code uses, so the whole path store -> report can be tested.

`python -m analysis.synthetic PATH` writes a demo store to PATH/mlflow.db.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from mlflow import MlflowClient
from mlflow.entities import Metric, Param

from analysis.labels import LEARNED
from analysis.scenarios import PAPER_CV_RATIO
from hgm_repro.contracts.names import REPORTED_METRICS as EPISODE_COLUMNS


@dataclass
class SyntheticSpec:
    """Per-model effect sizes; the defaults make every claim of the paper true."""

    seeds: tuple[int, ...] = (0, 1, 2, 3)
    scenarios: tuple[str, ...] = ("1", "2", "3", "4", "5")
    models: tuple[str, ...] = ("proposed", "min", "coordinate", "human")
    # Test episode return = base + slope * CV ratio + seed noise.
    return_base: dict[str, float] = field(default_factory=lambda: {
        "proposed": 1900.0, "min": 1860.0, "coordinate": 1840.0, "human": 1500.0, "idm_mobil": 1700.0})
    return_slope: dict[str, float] = field(default_factory=lambda: {
        "proposed": 80.0, "min": 0.0, "coordinate": 20.0, "human": 0.0, "idm_mobil": 0.0})
    speed: dict[str, float] = field(default_factory=lambda: {
        "proposed": 74.0, "min": 70.0, "coordinate": 68.0, "human": 55.0, "idm_mobil": 62.0})
    lane_changes: dict[str, float] = field(default_factory=lambda: {
        "proposed": 2.0, "min": 5.0, "coordinate": 4.0, "human": 8.0, "idm_mobil": 3.0})
    overtakes: dict[str, float] = field(default_factory=lambda: {
        "proposed": 9.0, "min": 7.0, "coordinate": 7.5, "human": 2.0, "idm_mobil": 5.0})
    # Training: curve time constant (fraction of training) and overtake-curve wiggle.
    tau: dict[str, float] = field(default_factory=lambda: {"proposed": 0.1, "min": 0.3, "coordinate": 0.3})
    overtake_wiggle: dict[str, float] = field(default_factory=lambda: {"proposed": 0.1, "min": 1.5,
                                                                       "coordinate": 0.1})
    noise: float = 0.005  # relative seed-to-seed noise of every metric
    curve_noise: float = 1.0  # scales the step-to-step jitter of the training curves (0: smooth)
    total_steps: int = 100_000
    log_points: int = 40
    episodes: int = 4
    rng_seed: int = 7
    experiment: str = "synthetic"  # the preset the runs name (`experiment.name`): a rung of the scale ladder, say


def synthetic_frames(spec: SyntheticSpec) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """(evals, curves, episodes) shaped as `StoreData` holds them; run ids are placeholders."""
    rng = np.random.default_rng(spec.rng_seed)
    eval_rows, episode_rows, curve_frames = [], [], []
    for model in spec.models:
        for seed in spec.seeds:
            # One offset per seed and model, shared by all scenarios: a good seed is good everywhere.
            seed_effect = rng.normal(0.0, spec.noise)
            for scenario in spec.scenarios:
                cv = PAPER_CV_RATIO.get(scenario, 0.5)
                means = {
                    "episode_return": spec.return_base.get(model, 1600.0) + spec.return_slope.get(model, 0.0) * cv,
                    "avg_speed_kmh": spec.speed.get(model, 60.0),
                    "lane_changes": spec.lane_changes.get(model, 4.0),
                    "overtakes": spec.overtakes.get(model, 5.0),
                    "collisions": 0.05,
                    "dangerous_actions": 1.0,
                }
                means["distance_m"] = means["avg_speed_kmh"] / 3.6 * 120.0
                run_id = f"{spec.experiment}-{model}-{scenario}-{seed}"
                eps = {}
                for metric, mean in means.items():
                    noise = seed_effect + rng.normal(0.0, spec.noise, size=spec.episodes) * 0.5
                    eps[metric] = mean * (1.0 + noise)
                for i in range(spec.episodes):
                    episode_rows.append({"run_id": run_id, "model": model, "scenario": scenario, "seed": seed,
                                         "episode": i, **{m: float(v[i]) for m, v in eps.items()}})
                eval_rows.append({"run_id": run_id, "model": model, "scenario": scenario, "seed": seed,
                                  "experiment": spec.experiment, "train_key": _train_key(spec, model),
                                  "git_commit": "abc1234",
                                  **{m: float(np.mean(v)) for m, v in eps.items()}, "n_episodes": spec.episodes})
            if model in spec.tau:
                curve_frames.append(_curves(spec, model, seed, rng))
    evals = pd.DataFrame(eval_rows)
    episodes = pd.DataFrame(episode_rows)
    curves = pd.concat(curve_frames, ignore_index=True) if curve_frames else pd.DataFrame(
        columns=["run_id", "model", "seed", "train_key", "metric", "step", "value"])
    return evals, curves, episodes


def _train_key(spec: SyntheticSpec, model: str) -> str:
    # One training config per model and preset, as the app's train_key is.
    return f"tk-{model}" if spec.experiment == SyntheticSpec.experiment else f"tk-{model}-{spec.experiment}"


def _curves(spec: SyntheticSpec, model: str, seed: int, rng: np.random.Generator) -> pd.DataFrame:
    steps = np.linspace(spec.total_steps / spec.log_points, spec.total_steps, spec.log_points).astype(int)
    t = steps / spec.total_steps
    rise = 1.0 - np.exp(-t / spec.tau[model])

    def jitter(scale: float) -> np.ndarray:
        return rng.normal(0.0, scale * spec.curve_noise, size=t.size)

    values = {
        "avg_speed_kmh": 50.0 + (spec.speed[model] - 50.0) * rise + jitter(0.3),
        "lane_changes": 20.0 - (20.0 - spec.lane_changes[model]) * rise + jitter(0.2),
        "overtakes": 1.0 + (spec.overtakes[model] - 1.0) * rise + jitter(spec.overtake_wiggle[model]),
        "episode_return": 500.0 + 1400.0 * rise + jitter(10.0),
        "loss": 1.0 / (1.0 + 10 * t) + np.abs(jitter(0.01)),
        "epsilon": np.maximum(0.1, 1.0 - 0.9 * t),
        "steps_per_s": 400.0 + jitter(5.0),
    }
    return pd.concat([pd.DataFrame({"run_id": f"{spec.experiment}-{model}-train-{seed}", "model": model,
                                    "seed": seed, "train_key": _train_key(spec, model), "metric": metric,
                                    "step": steps, "value": v})
                      for metric, v in values.items()], ignore_index=True)


def _log_batches(client: MlflowClient, run_id: str, metrics: list[Metric], params: list[Param]) -> None:
    for i in range(0, max(len(metrics), 1), 900):  # MLflow accepts at most 1000 metrics per batch
        client.log_batch(run_id, metrics=metrics[i:i + 900], params=params if i == 0 else [])


def write_store(root: Path, spec: SyntheticSpec | None = None, experiment: str = "hgm_repro",
                with_parent: bool = True) -> str:
    """Log a synthetic sweep to `root/mlflow.db` (artifacts under `root/artifacts`); returns the URI."""
    spec = spec or SyntheticSpec()
    root.mkdir(parents=True, exist_ok=True)
    uri = f"sqlite:///{root.resolve() / 'mlflow.db'}"
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name(experiment)
    exp_id = exp.experiment_id if exp else client.create_experiment(
        experiment, artifact_location=(root.resolve() / "artifacts").as_uri())
    evals, curves, episodes = synthetic_frames(spec)
    parent = client.create_run(exp_id, tags={"sweep": "synthetic"}).info.run_id if with_parent else None
    config_text = "simulator:\n  lanes: 5\n  v_min_kmh: 40.0\nlearner:\n  lr: 0.0025\n"
    params = [Param("simulator.lanes", "5"), Param("simulator.v_min_kmh", "40.0"),
              Param("simulator.vehicle_types.CHV.a_lon", "2.0"), Param("simulator.vehicle_types.AHV.a_lon", "4.0"),
              Param("learner.lr", "0.0025")]

    def tags(model: str, scenario: str, seed: int, stage: str) -> dict[str, str]:
        t = {"model": model, "scenario": scenario, "seed": str(seed), "stage": stage,
             "train_key": _train_key(spec, model), "git_commit": "abc1234", "preset": spec.experiment}
        if parent:
            t["mlflow.parentRunId"] = parent
        return t

    for (model, seed), group in curves.groupby(["model", "seed"]):
        run_id = client.create_run(exp_id, tags=tags(model, "train", int(seed), "train")).info.run_id
        metrics = [Metric(f"train/{r.metric}", float(r.value), 0, int(r.step)) for r in group.itertuples()]
        _log_batches(client, run_id, metrics, params + [Param("params/total", "123456")])
        client.set_terminated(run_id)
    for row in evals.itertuples(index=False):
        run_id = client.create_run(exp_id, tags=tags(row.model, row.scenario, int(row.seed), "eval")).info.run_id
        metrics = [Metric(f"eval/{m}", float(getattr(row, m)), 0, 0) for m in EPISODE_COLUMNS]
        # Every evaluation run resolves its preset, the non-learning hosts' too; the training runs log only what
        # identifies a training, which holds no preset name.
        own = [Param("model.name", row.model), Param("experiment.name", row.experiment)]
        _log_batches(client, run_id, metrics, own + (params if row.model in LEARNED else []))
        eps = episodes[episodes["run_id"] == row.run_id][list(EPISODE_COLUMNS)]
        client.log_text(run_id, eps.to_csv(index=False), "episodes.csv")
        client.log_text(run_id, config_text + f"model:\n  name: {row.model}\n", "config.yaml")
        client.set_terminated(run_id)
    if parent:
        client.set_terminated(parent)
    return uri


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "synthetic_store")
    print(write_store(target))
