"""Interrupted anywhere, nothing lost (subprocesses, real signals, real SQLite): a requeue through
submitit's local executor on SIGUSR2, four parallel jobs on one store, and sweeps SIGKILLed at
random moments and then run to completion."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import time
from collections import defaultdict
from pathlib import Path

import pytest

from tests.helpers.cli import TINY, by_stage, check_store, client, command, environment, hgm


def test_sigusr2_under_submitit_requeues_and_the_requeued_job_resumes(tmp_path: Path) -> None:
    """SLURM's time-limit signal, through hydra-submitit-launcher's local executor: the job stops at a
    safe point, writes last.pt, closes its run KILLED and hands the signal to submitit, which requeues
    it (its controller restarts the task); the requeued job resumes the same training run."""
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    from hgm_repro.contracts.checkpoint import load_checkpoint

    # Long enough that the signal, sent once the first last.pt exists, lands in training on an idle
    # machine too (at 256 steps the training could end first, and the requeued job had nothing to resume).
    args = ("-m", *TINY, "learner.total_steps=2048", "hydra/launcher=submitit_local",
            "hydra.launcher.timeout_min=30", "hydra.sweep.dir=sweep")
    sweep = subprocess.Popen(command(*args), cwd=tmp_path, env=environment(), stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 400
        while not list((tmp_path / "checkpoints").glob("*/last.pt")):  # training is under way
            assert sweep.poll() is None, sweep.stdout.read()[-3000:]
            assert time.monotonic() < deadline, "no checkpoint written in time"
            time.sleep(0.2)
        (id_file,) = (tmp_path / "checkpoints").glob("*/mlflow_run_id")
        run_id = id_file.read_text().strip()
        task_pid = int(client(tmp_path).get_run(run_id).data.tags["pid"])  # submitit's task process
        os.kill(task_pid, signal.SIGUSR2)  # what submitit's controller sends signal_delay_s before a timeout
        output, _ = sweep.communicate(timeout=600)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
    assert sweep.returncode == 0, output[-3000:]
    logs = "\n".join(p.read_text() for p in (tmp_path / "sweep" / ".submitit").rglob("*.out"))
    logs += "\n".join(p.read_text() for p in (tmp_path / "sweep" / ".submitit").rglob("*.err"))
    assert "job interrupted (interrupted by SIGUSR2)" in logs, logs[-3000:]
    assert "Requeued job" in logs, logs[-3000:]
    runs = check_store(tmp_path, {("proposed", "train", "0")}, train_keys=1)
    (train,) = by_stage(runs, "train")
    assert train.info.run_id == run_id and train.data.tags["resumes"] == "1"
    assert load_checkpoint(id_file.parent / "final.pt")["env_steps"] == 2048


def test_four_parallel_jobs_on_one_sqlite_store(tmp_path: Path) -> None:
    """Two keys, each wanted by two of four jobs running at once: each trained once, no lock error shown."""
    out = hgm(tmp_path, "-m", *TINY, "model=proposed,min", "scenario=1,2", "hydra/launcher=joblib",
              "hydra.launcher.n_jobs=4")
    text = out.stdout + out.stderr
    for symptom in ("database is locked", "Traceback", "OperationalError", "Timeout"):
        assert symptom not in text, text[-3000:]
    runs = check_store(tmp_path, {(m, s, "0") for m in ("proposed", "min") for s in ("1", "2")}, train_keys=2)
    assert len(by_stage(runs, "train")) == 2
    how = defaultdict(list)
    for run in by_stage(runs, "eval"):
        how[run.data.tags["train_key"]].append(run.data.tags["training"])
    assert all(sorted(v) == ["reused", "trained"] for v in how.values()), how


# Fault injection: a sweep of two training keys and four evaluations, SIGKILLed (the whole
# process group, no chance to clean up) at several random moments, then run to completion.
FAULT_SWEEP = ("-m", *TINY, "model=proposed", "scenario=1,2", "seed=0,1", "hydra.sweep.dir=sweep")
FAULT_CELLS = {("proposed", s, seed) for s in ("1", "2") for seed in ("0", "1")}
ROUNDS = int(os.environ.get("HGM_FAULT_ROUNDS", "1"))


def _kill_at(launch: Path, rng: random.Random, moment: str, log: Path) -> None:
    """Start the sweep and SIGKILL it at `moment`: a random time, or while a checkpoint is being written."""
    sweep = subprocess.Popen(command(*FAULT_SWEEP), cwd=launch, env=environment(), stdout=log.open("a"),
                             stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + (rng.uniform(3.0, 60.0) if moment == "random" else 240.0)
    while sweep.poll() is None and time.monotonic() < deadline:
        if moment == "checkpoint write" and list((launch / "checkpoints").glob("*/.*.pt.tmp-*")):
            break
        time.sleep(0.002 if moment == "checkpoint write" else 0.05)
    if sweep.poll() is None:
        os.killpg(sweep.pid, signal.SIGKILL)
    sweep.wait()
    with log.open("a") as f:
        f.write(f"\n==== SIGKILL ({moment}) after the line above; exit {sweep.returncode}\n")


@pytest.mark.slow
@pytest.mark.parametrize("round_", range(ROUNDS))
def test_sweep_killed_at_random_moments_then_completed(tmp_path: Path, round_: int) -> None:
    rng = random.Random(int.from_bytes(os.urandom(4), "little"))
    log = tmp_path / "kills.log"
    for moment in rng.sample(["random", "random", "random", "checkpoint write"], k=4):
        _kill_at(tmp_path, rng, moment, log)
    out = hgm(tmp_path, *FAULT_SWEEP)
    with log.open("a") as f:
        f.write(out.stdout + out.stderr)
    check_store(tmp_path, FAULT_CELLS, train_keys=2)
