"""The command line in a subprocess, as a user launches it, and the MLflow store such a launch leaves."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

from . import REPO_ROOT

# Smoke sizes cut further: a job is a few seconds of training and evaluation on a busy CPU.
TINY = ("experiment=smoke", "tracking.log_gif=false", "learner.total_steps=128", "learner.warmup_steps=32",
        "learner.batch_size=8", "logging.checkpoint_every=32", "logging.log_every=32", "eval.test_steps=32",
        "runtime.torch_threads=1")


def command(*args: str) -> list[str]:
    return [sys.executable, "-m", "hgm_repro", *args]


def environment(**extra: str) -> dict[str, str]:
    """This process's environment with the checkout first on PYTHONPATH, plus `extra`."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")]), **extra}


def hgm(cwd: Path, *args: str, check: bool = True, timeout: float = 900,
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """`python -m hgm_repro *args` in `cwd`, with `env` added to the environment; with `check`, its exit
    code must be 0."""
    out = subprocess.run(command(*args), cwd=cwd, env=environment(**(env or {})), capture_output=True, text=True,
                         timeout=timeout)
    if check:
        assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-5000:]
    return out


def client(launch: Path):
    from mlflow.tracking import MlflowClient

    return MlflowClient(tracking_uri=f"sqlite:///{launch.resolve()}/mlflow.db")


def store_runs(launch: Path) -> list:
    store = client(launch)
    experiment = store.get_experiment_by_name("hgm_repro")
    return store.search_runs([experiment.experiment_id], max_results=1000)


def by_stage(runs: list, stage: str) -> list:
    return [r for r in runs if r.data.tags.get("stage") == stage]


def check_store(launch: Path, cells: set[tuple[str, str, str]], train_keys: int) -> list:
    """One FINISHED training per key, one FINISHED evaluation per cell, nothing RUNNING, each metric
    step logged once, and every checkpoint on disk complete."""
    from hgm_repro.contracts.checkpoint import load_checkpoint

    runs = store_runs(launch)
    assert [r.info.run_name for r in runs if r.info.status == "RUNNING"] == []
    trainings = Counter(r.data.tags["train_key"] for r in by_stage(runs, "train") if r.info.status == "FINISHED")
    assert len(trainings) == train_keys and set(trainings.values()) == {1}, trainings
    evaluations = Counter((r.data.tags["model"], r.data.tags["scenario"], r.data.tags["seed"])
                          for r in by_stage(runs, "eval") if r.info.status == "FINISHED")
    assert set(evaluations) == cells and set(evaluations.values()) == {1}, evaluations
    store = client(launch)
    for run in by_stage(runs, "train"):
        for key in run.data.metrics:
            steps = Counter(m.step for m in store.get_metric_history(run.info.run_id, key))
            assert [s for s, n in steps.items() if n > 1] == [], (run.info.run_id, key, steps)
    checkpoints = sorted((launch / "checkpoints").glob("*/*.pt"))
    assert checkpoints
    for path in checkpoints:
        load_checkpoint(path)  # raises on a half-written or foreign file
    return runs
