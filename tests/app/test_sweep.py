"""Sweeps end to end (subprocesses, smoke preset): train once per key, evaluate every job,
parallel jobs that share a key, and a training killed mid-way that resumes."""

from __future__ import annotations

import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.helpers.cli import by_stage, command, environment, hgm, store_runs

JOB_TAGS = ("model", "scenario", "seed", "stage", "train_key", "git_commit", "git_dirty")
EVAL_METRICS = ("eval/avg_speed_kmh", "eval/lane_changes", "eval/overtakes", "eval/collisions",
                "eval/dangerous_actions", "eval/episode_return")


def check_sweep(launch: Path, trainings: int, evaluations: int) -> list:
    from mlflow.tracking import MlflowClient

    runs = store_runs(launch)
    train, evals = by_stage(runs, "train"), by_stage(runs, "eval")
    parents = [r for r in runs if r.data.tags.get("sweep") == "true"]
    assert len(train) == trainings and len(evals) == evaluations and len(parents) == 1
    assert {r.info.status for r in runs} == {"FINISHED"}
    # One parent run groups the sweep's runs in the MLflow UI.
    assert {r.data.tags["mlflow.parentRunId"] for r in train + evals} == {parents[0].info.run_id}
    assert len({r.data.tags["train_key"] for r in train}) == trainings
    # Every evaluation of a learned model used a training of its key; exactly one per key trained.
    keys = {r.data.tags["train_key"]: r.info.run_id for r in train}
    learned = [r for r in evals if r.data.tags["training"] != "none"]
    assert all(keys[r.data.tags["train_key"]] == r.data.tags["train_run_id"] for r in learned)
    assert sum(r.data.tags["training"] == "trained" for r in learned) == trainings
    client = MlflowClient(tracking_uri=f"sqlite:///{launch.resolve()}/mlflow.db")
    for run in train + evals:
        for tag in JOB_TAGS:
            assert tag in run.data.tags, (tag, run.data.tags)
        assert run.data.tags["git_commit"] != ""
        assert "learner.lr" in run.data.params and "seed" in run.data.params
    for run in train:
        assert run.data.tags["scenario"] == "train"
        assert any(k.startswith("train/") for k in run.data.metrics), run.data.metrics
        assert "params/total" in run.data.params and not any(k.startswith("params/") for k in run.data.metrics)
        names = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert "config.yaml" in names
        saved = [a.path for a in client.list_artifacts(run.info.run_id, "checkpoint")]
        assert saved in (["checkpoint/final.pt"], ["checkpoint/best.pt", "checkpoint/final.pt"])
    # The parent run: named by its sweep directory, described, and holding the grid's means.
    parent = parents[0]
    assert parent.info.run_name.startswith("sweep ") and "A sweep" in parent.data.tags["mlflow.note.content"]
    assert re.fullmatch(r"sweep \d{4}-\d\d-\d\d \d\d:\d\d:\d\d", parent.info.run_name)
    grid = {(r.data.tags["model"], r.data.tags["scenario"]) for r in evals}
    assert parent.data.metrics == {}  # the grid's means are a table in its description
    for model, scenario in grid:
        returns = [r.data.metrics["eval/episode_return"] for r in evals
                   if (r.data.tags["model"], r.data.tags["scenario"]) == (model, scenario)]
        assert f"| {model} | {scenario} | {len(returns)} | {sum(returns) / len(returns):.4g} |" in \
            parent.data.tags["mlflow.note.content"]
    for run in evals:
        assert run.info.run_name == (f"{run.data.tags['model']} seed{run.data.tags['seed']} "
                                     f"scenario{run.data.tags['scenario']} eval")
        for metric in EVAL_METRICS:
            assert metric in run.data.metrics, (metric, run.data.metrics)
        names = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert {"config.yaml", "episodes.csv"} <= names
        assert "episode.gif" in names or run.data.tags.get("gif", "").startswith("skipped")
    return runs


def test_small_parallel_sweep_trains_each_key_once(tmp_path: Path) -> None:
    """Two jobs with the same key run at once: one trains, the other waits and reuses it."""
    hgm(tmp_path, "-m", "experiment=smoke", "model=proposed,human", "scenario=1,5",
        "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")
    runs = check_sweep(tmp_path, trainings=1, evaluations=4)
    assert sorted(r.data.tags["training"] for r in by_stage(runs, "eval")) == ["none", "none", "reused", "trained"]
    # Each job's own config names the parent run too: a worker that does not inherit the launching
    # process's environment (Ray's, on a cluster started beforehand) still finds it.
    from omegaconf import OmegaConf

    (parent,) = [r for r in runs if r.data.tags.get("sweep") == "true"]
    saved = sorted(tmp_path.glob("multirun/*/*/*/.hydra/hydra.yaml"))
    assert len(saved) == 4
    for path in saved:
        assert OmegaConf.load(path).hydra.job.env_set["HGM_REPRO_PARENT_RUN_ID"] == parent.info.run_id
    # A second launch finds every training finished: it only evaluates.
    hgm(tmp_path, "experiment=smoke", "model=proposed", "scenario=3")
    assert len(by_stage(store_runs(tmp_path), "train")) == 1


def test_smoke_grid_2_models_2_scenarios_2_seeds(tmp_path: Path) -> None:
    out = hgm(tmp_path, "-m", "experiment=smoke", "model=proposed,min", "scenario=1,5", "seed=0,1",
              "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")
    runs = check_sweep(tmp_path, trainings=4, evaluations=8)
    # The log says where to look once, and carries no per-job warnings or notices.
    log = out.stdout + out.stderr
    assert log.count("viewStateShareKey=grid") == 1, log[-3000:]
    for noise in ("Pickle", "Initialized LazyTensorStorage", "Creating initial MLflow database"):
        assert noise not in log, noise
    # A finished training keeps one full checkpoint (final.pt), and best.pt as weights only.
    for directory in (tmp_path / "checkpoints").iterdir():
        assert (directory / "final.pt").is_file() and not (directory / "last.pt").exists(), directory
    evals = by_stage(runs, "eval")
    assert sorted((r.data.tags["model"], r.data.tags["scenario"], r.data.tags["seed"]) for r in evals) == sorted(
        (m, s, seed) for m in ("proposed", "min") for s in ("1", "5") for seed in ("0", "1"))


# A training long enough to be caught mid-way: smoke sizes, more steps, frequent checkpoints.
# The job is stopped as soon as its first last.pt (step 64) appears.
LONGER = ("experiment=smoke", "learner.total_steps=256", "logging.checkpoint_every=64", "tracking.log_gif=false")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_killed_training_resumes_into_one_finished_run(tmp_path: Path, sig: signal.Signals) -> None:
    job = subprocess.Popen(command(*LONGER), cwd=tmp_path, env=environment(),
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 300
    while not list((tmp_path / "checkpoints").glob("*/last.pt")):
        assert job.poll() is None, job.stdout.read()[-3000:]
        assert time.monotonic() < deadline, "no checkpoint written in time"
        time.sleep(0.5)
    job.send_signal(sig)
    output, _ = job.communicate(timeout=120)
    assert job.returncode == (128 + signal.SIGTERM if sig == signal.SIGTERM else -signal.SIGKILL), output[-3000:]
    (stopped,) = by_stage(store_runs(tmp_path), "train")
    # SIGTERM: the job closes its run itself. SIGKILL: nobody can, until the next job does.
    assert stopped.info.status == ("KILLED" if sig == signal.SIGTERM else "RUNNING")

    out = hgm(tmp_path, *LONGER)
    assert "training=resumed" in out.stdout + out.stderr
    runs = store_runs(tmp_path)
    (train,) = by_stage(runs, "train")
    assert train.info.run_id == stopped.info.run_id and train.info.status == "FINISHED"
    assert train.data.tags["resumes"] == "1"
    (evaluation,) = by_stage(runs, "eval")
    assert evaluation.info.status == "FINISHED" and evaluation.data.tags["train_run_id"] == train.info.run_id



def test_optuna_preset_tunes_on_the_validation_return(tmp_path: Path) -> None:
    import yaml
    from mlflow.tracking import MlflowClient

    pytest.importorskip("hydra_plugins.hydra_optuna_sweeper", reason="pip install '.[optuna]'")
    hgm(tmp_path, "-m", "hparams_search=optuna_val", "experiment=smoke", "hydra.sweeper.n_trials=2",
        "hydra.sweeper.sampler.n_startup_trials=2", "eval.val_every=128", "tracking.log_gif=false")
    runs = store_runs(tmp_path)
    train, evals = by_stage(runs, "train"), by_stage(runs, "eval")
    assert len(train) == 2 and {r.data.tags["scenario"] for r in evals} == {"train"}  # no test scenario seen
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path.resolve()}/mlflow.db")
    best_val = max(max(m.value for m in client.get_metric_history(r.info.run_id, "val/episode_return"))
                   for r in train)
    (results,) = (tmp_path / "multirun").rglob("optimization_results.yaml")
    assert yaml.safe_load(results.read_text())["best_value"] == pytest.approx(best_val)
