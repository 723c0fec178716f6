"""The study scripts that outlast a session: their refusals of bad input, and the scale ladder's state
carried across a stop and a new machine (a store that is gone, restored from the kept state)."""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import pytest

STUDIES = Path(__file__).resolve().parents[2] / "studies"


def run(script: str, *args: str, env: dict[str, str] | None = None, timeout: int = 60) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(STUDIES / script), *args], capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **(env or {})})


@pytest.mark.parametrize(("args", "said"), [
    (("paper", "5"), "rung 'paper' is not one of: paper_steps paper_pixels"),
    (("paper_steps", "soon"), "MINUTES 'soon' must be a whole number of minutes"),
    (("paper_steps", "0"), "MINUTES '0' must be a whole number of minutes"),
    (("paper_steps", "extend", "soon"), "extend 'soon' must be a whole number of minutes, at least 1"),
    (("paper_steps", "extend"), "extend '' must be a whole number of minutes"),
])
def test_the_ladder_refuses_a_bad_rung_or_time(args, said):
    done = run("ladder.sh", *args)
    assert done.returncode == 2 and said in done.stderr


@pytest.mark.parametrize("flag", ["-h", "--help"])
def test_the_ladders_help_is_its_header(flag):
    done = run("ladder.sh", flag)
    assert done.returncode == 0 and done.stderr == ""
    assert done.stdout.startswith("One rung of the scale ladder")
    assert "bash research/studies/ladder.sh paper_steps extend 15" in done.stdout
    assert "set -euo pipefail" not in done.stdout and "#" not in done.stdout.split("\n", 1)[0]


def test_a_sweep_that_ends_before_its_time_leaves_no_timer_behind(tmp_path):
    env = {"LADDER_RUNS": str(tmp_path / "runs"), "LADDER_STATE": str(tmp_path / "state")}
    timer = ["pgrep", "-fx", "sleep 5820"]  # 97 minutes: a number nothing else here sleeps
    try:
        done = run("ladder.sh", "paper_steps", "97", "model=nosuch", env=env, timeout=180)
        assert done.returncode == 0 and "the sweep ended with status 2 " in done.stdout, done.stderr  # refused
        assert done.stderr == ""  # nor a word from the stopped timer
        assert subprocess.run(timer, capture_output=True).returncode == 1  # no sleep outlives the sweep
        assert not (tmp_path / "runs" / "paper_steps" / "sweep.deadline").exists()  # nor a stop to extend
    finally:
        subprocess.run(["pkill", "-fx", "sleep 5820"], capture_output=True)


def test_extend_moves_a_running_sweeps_stop_and_refuses_without_one(tmp_path):
    env = {"LADDER_RUNS": str(tmp_path / "runs"), "LADDER_STATE": str(tmp_path / "state")}
    deadline = tmp_path / "runs" / "paper_steps" / "sweep.deadline"
    nothing = run("ladder.sh", "paper_steps", "extend", "10", env=env)  # no store, no sweep
    assert nothing.returncode == 2 and "no paper_steps sweep is running" in nothing.stderr
    assert not deadline.exists()
    # A sweep's process group, as the script starts one: its own session, still running.
    sweep = subprocess.Popen(["setsid", "sleep", "300"])
    try:
        deadline.parent.mkdir(parents=True)
        deadline.write_text(f"{sweep.pid} 2000000000\n")
        done = run("ladder.sh", "paper_steps", "extend", "10", env=env)
        assert done.returncode == 0, done.stderr
        assert deadline.read_text() == f"{sweep.pid} {2000000000 + 600}\n"
        assert "the paper_steps sweep now stops at 03:43:20 UTC" in done.stdout  # 2033-05-18 03:33:20 + 10 min
    finally:
        sweep.kill()
        sweep.wait()
    # The same file once its sweep has ended (a stopped session's leftover): refused, the stop left as it was.
    gone = run("ladder.sh", "paper_steps", "extend", "10", env=env)
    assert gone.returncode == 2 and "no paper_steps sweep is running" in gone.stderr
    assert deadline.read_text() == f"{sweep.pid} {2000000000 + 600}\n"


def test_the_retest_names_the_models_it_knows():
    done = run("retest_grid.sh", "proposed", "nosuch")
    assert done.returncode == 2 and "model 'nosuch' has no config; allowed:" in done.stderr
    assert "proposed_guarded" in done.stderr
    assert run("retest_grid.sh").returncode == 2


@pytest.mark.slow
def test_a_rung_stopped_by_its_time_resumes_on_a_new_machine_from_the_kept_state(tmp_path):
    env = {"LADDER_RUNS": str(tmp_path / "runs"), "LADDER_STATE": str(tmp_path / "state"), "LADDER_NICE": "1"}
    ours = Path("/proc/self/autogroup").read_text() if Path("/proc/self/autogroup").exists() else None
    # Two scenarios of one seed: one job trains, the other waits for its training, and the stop reaches both.
    tiny = ("learner.total_steps=40000", "learner.warmup_steps=100", "eval.test_steps=64", "eval.test_envs=4",
            "seed=0", "scenario='1','2'", "logging.checkpoint_every=200", "tracking.log_gif=false")
    first = run("ladder.sh", "paper_steps", "1", *tiny, env=env, timeout=240)
    assert first.returncode == 0, first.stderr
    assert "ended with status 143" in first.stdout  # stopped by its time, not finished
    if ours is not None:  # the sweep's priority was lowered (a little: it must still train), not the caller's
        assert Path("/proc/self/autogroup").read_text() == ours
    state = tmp_path / "state" / "paper_steps"
    kept = sorted(p.name for p in (state / "trainings").glob("*/*"))
    assert kept == ["last.pt", "mlflow_run_id"] and (state / "mlflow.db").is_file()
    # What is kept is what the stopped job wrote last: its last.pt, and its run marked KILLED.
    store = tmp_path / "runs" / "paper_steps"
    (written,) = store.glob("checkpoints/*/last.pt")
    assert (state / "trainings" / written.parent.name / "last.pt").read_bytes() == written.read_bytes()
    assert training_statuses(state) == [("KILLED",)] and running(state) == []
    shutil.rmtree(tmp_path / "runs")  # a new machine: the store is gone
    second = run("ladder.sh", "paper_steps", "1", *tiny, env=env, timeout=240)
    assert second.returncode == 0 and "restored paper_steps" in second.stdout
    log = next((tmp_path / "runs" / "paper_steps").glob("sweep-*.log")).read_text()
    assert "resuming training run" in log
    # The resumed training, stopped again, is kept KILLED too: nothing the next session reads as running.
    assert training_statuses(state) == [("KILLED",)] and running(state) == []
    only_kept = run("ladder.sh", "paper_steps", "keep", env=env)  # the store's state again, no sweep
    assert only_kept.returncode == 0 and "commit" in only_kept.stdout and running(state) == []


def test_the_kept_state_leaves_out_a_finished_trainings_large_networks(tmp_path):
    store = tmp_path / "runs" / "paper_pixels"
    sizes = {"large_finished": {"final.pt": 15, "best.pt": 15}, "small_finished": {"final.pt": 2, "best.pt": 2},
             "large_unfinished": {"last.pt": 30}}
    for training, files in sizes.items():
        (store / "checkpoints" / training).mkdir(parents=True)
        (store / "checkpoints" / training / "mlflow_run_id").write_text(training)
        for name, mb in files.items():
            with open(store / "checkpoints" / training / name, "wb") as f:
                f.truncate(mb * 1024 * 1024)  # sparse: the size is what counts
    sqlite3.connect(store / "mlflow.db").close()
    env = {"LADDER_RUNS": str(tmp_path / "runs"), "LADDER_STATE": str(tmp_path / "state")}
    done = run("ladder.sh", "paper_pixels", "keep", env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "large_finished's networks (30 MB) are not kept" in done.stdout
    trainings = tmp_path / "state" / "paper_pixels" / "trainings"
    kept = {training: sorted(p.name for p in (trainings / training).iterdir()) for training in sizes}
    assert kept == {"large_finished": ["mlflow_run_id"], "small_finished": ["best.pt", "final.pt", "mlflow_run_id"],
                    "large_unfinished": ["last.pt", "mlflow_run_id"]}


@pytest.mark.slow
def test_an_extended_sweep_is_stopped_at_its_later_time(tmp_path):
    env = {"LADDER_RUNS": str(tmp_path / "runs"), "LADDER_STATE": str(tmp_path / "state")}
    # One training far too long to end in two minutes, so that only the timer ends it.
    tiny = ("learner.total_steps=400000", "learner.warmup_steps=100", "eval.test_steps=64", "eval.test_envs=4",
            "seed=0", "scenario='1'", "tracking.log_gif=false")
    deadline = tmp_path / "runs" / "paper_steps" / "sweep.deadline"
    sweep = subprocess.Popen(["bash", str(STUDIES / "ladder.sh"), "paper_steps", "1", *tiny], text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, **env})
    try:
        for _ in range(300):
            if deadline.exists():
                break
            time.sleep(0.1)
        first_stop = int(deadline.read_text().split()[1])
        more = run("ladder.sh", "paper_steps", "extend", "1", env=env)
        assert more.returncode == 0, more.stderr
        assert int(deadline.read_text().split()[1]) == first_stop + 60
        out, err = sweep.communicate(timeout=300)
    finally:
        if sweep.poll() is None:  # a failed check: stop the training too, not only the script that started it
            stop_group(deadline)
            sweep.kill()
    assert sweep.returncode == 0, err
    assert "ended with status 143 after 2 minutes" in out  # stopped by the later time, not the first
    assert time.time() >= first_stop + 60 and not deadline.exists()


def stop_group(deadline: Path) -> None:
    """Kill the sweep's process group named in its stop file (its training runs in a session of its own)."""
    try:
        os.killpg(int(deadline.read_text().split()[0]), signal.SIGKILL)
    except (FileNotFoundError, ValueError, IndexError, ProcessLookupError):
        pass  # no file, a half-written one, or a group already gone: nothing left to stop


def training_statuses(state: Path) -> list[tuple[str]]:
    with sqlite3.connect(state / "mlflow.db") as db:
        return db.execute("SELECT r.status FROM runs r JOIN tags t ON t.run_uuid = r.run_uuid "
                          "WHERE t.key = 'stage' AND t.value = 'train'").fetchall()


def running(state: Path) -> list[tuple[str]]:
    with sqlite3.connect(state / "mlflow.db") as db:
        return db.execute("SELECT name FROM runs WHERE status = 'RUNNING'").fetchall()


@pytest.mark.parametrize(("files_mb", "commits"), [
    ({"a": 9, "b": 9, "c": 9, "d": 9, "e": 9, "f": 9}, True),  # 54 MB in all, no file near git's limit
    ({"a": 2, "b": 60}, False),  # one paper-sized network
])
def test_the_kept_state_is_refused_for_its_largest_file_not_its_total(tmp_path, files_mb, commits):
    store = tmp_path / "runs" / "paper_steps"
    for training, mb in files_mb.items():
        (store / "checkpoints" / training).mkdir(parents=True)
        with open(store / "checkpoints" / training / "last.pt", "wb") as f:
            f.write(bytes(mb * 1024 * 1024))  # written, not sparse: the disk holds what a push carries
    sqlite3.connect(store / "mlflow.db").close()
    env = {"LADDER_RUNS": str(tmp_path / "runs"), "LADDER_STATE": str(tmp_path / "state")}
    done = run("ladder.sh", "paper_steps", "keep", env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    if commits:
        assert "to carry the rung to the next session" in done.stdout
        assert "too large to commit" not in done.stderr
    else:
        assert "trainings/b/last.pt is 60 MB, more than LADDER_MAX_FILE_MB=50: too large to commit" in done.stderr
        assert "to carry the rung to the next session" not in done.stdout
