"""Grouped training in a sweep, end to end (subprocesses, smoke sizes): the store ends as a solo
sweep would leave it, also after a SIGKILL in the middle of the grouped training."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.helpers.cli import TINY, by_stage, check_store, command, environment, hgm, store_runs

GRID = ("-m", *TINY, "model=proposed,min", "seed=0,1,2", "scenario=1,5", "runtime.grouped=true",
        "hydra.sweep.dir=sweep")
CELLS = {(model, scenario, seed) for model in ("proposed", "min") for scenario in ("1", "5")
         for seed in ("0", "1", "2")}

pytestmark = pytest.mark.slow


def _check_grouped(launch: Path) -> None:
    runs = check_store(launch, CELLS, train_keys=6)
    trainings = [r for r in by_stage(runs, "train") if r.info.status == "FINISHED"]
    # every member trained by the sweep's grouped training, in at most 2 training processes
    assert {r.data.tags.get("grouped") for r in trainings} == {"3"}
    assert len({r.data.tags["trained_by_pid"] for r in trainings}) <= 2
    assert len({r.data.tags["train_key"] for r in trainings}) == 6


def _grid_until_a_checkpoint(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    """The grouped grid started in its own process group, returned once a member wrote last.pt."""
    log = tmp_path / "first.log"
    sweep = subprocess.Popen(command(*GRID), cwd=tmp_path, env=environment(), stdout=log.open("w"),
                             stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + 600
    while not list((tmp_path / "checkpoints").glob("*/last.pt")) and time.monotonic() < deadline:
        time.sleep(0.2)
        assert sweep.poll() is None, log.read_text()[-3000:]
    return sweep, log


def test_grouped_grid_leaves_the_store_a_solo_grid_would(tmp_path: Path) -> None:
    out = hgm(tmp_path, *GRID)
    assert "training the seeds of each model together" in out.stdout + out.stderr
    _check_grouped(tmp_path)


def test_grouped_grid_killed_mid_training_then_rerun(tmp_path: Path) -> None:
    sweep, _ = _grid_until_a_checkpoint(tmp_path)
    os.killpg(sweep.pid, signal.SIGKILL)
    sweep.wait()
    assert not [r for r in by_stage(store_runs(tmp_path), "eval")]  # killed before any job
    hgm(tmp_path, *GRID)
    _check_grouped(tmp_path)


def test_grouped_grid_stopped_by_sigterm_checkpoints_every_member_then_resumes(tmp_path: Path) -> None:
    from hgm_repro.contracts.checkpoint import load_checkpoint

    sweep, log = _grid_until_a_checkpoint(tmp_path)
    os.killpg(sweep.pid, signal.SIGTERM)
    assert sweep.wait(timeout=300) != 0
    stopped = [r for r in by_stage(store_runs(tmp_path), "train") if r.info.status != "FINISHED"]
    assert stopped and {r.info.status for r in stopped} == {"KILLED"}, log.read_text()[-3000:]
    # every stopped member wrote last.pt at the same safe point
    steps = {load_checkpoint(tmp_path / "checkpoints" / r.data.tags["train_key"] / "last.pt")["env_steps"]
             for r in stopped}
    assert len(steps) == 1, steps
    hgm(tmp_path, *GRID)
    _check_grouped(tmp_path)
