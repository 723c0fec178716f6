"""The grid on real cluster engines: a single-node SLURM cluster and a local Ray cluster.

Each test starts its engine, launches the same small grid (1 model x 2 scenarios x 1 seed: two jobs
that want one training, which one of them runs while the other waits for it) through the project's
launcher preset (`launcher=slurm`, `launcher=ray`), with the PostgreSQL-backed MLflow server as the
shared store, and stops the engine at the end. The store must then hold one FINISHED training per
key and one FINISHED evaluation per cell, under the sweep's parent run, each metric step logged once.

SLURM: the time limit is short and SLURM itself sends SIGUSR2 `signal_delay_s` before it (no
signal comes from this test): jobs stop at a safe point, write last.pt, submitit requeues them
(`scontrol requeue`), the requeued jobs resume, and `sacct` records the requeue.
Needs root, Debian's slurm-wlm, slurmdbd, munge and mariadb-server (`.ci/slurm_cluster.sh
install`), Ray needs the `ray` extra: `.ci/integration.sh` installs both.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT
from tests.helpers.cli import environment
from tests.helpers.servers import free_port, mlflow_server_on, postgres_cluster

pytestmark = pytest.mark.integration
SLURM_SCRIPT = REPO_ROOT / ".ci" / "slurm_cluster.sh"
SEEDS = ("0",)
SCENARIOS = ("1", "2")
CELLS = {("proposed", s, seed) for s in SCENARIOS for seed in SEEDS}
GRID = ("-m", "experiment=smoke", "model=proposed", f"scenario={','.join(SCENARIOS)}", f"seed={','.join(SEEDS)}",
        "tracking.log_gif=false", "tracking.log_model=false", "runtime.torch_threads=1")
# SLURM: a training longer than one attempt (75-170 s on a 2-core machine, by its load), so that the
# time-limit signal reaches it, with checkpoints every few seconds so that each attempt makes progress.
SLURM_STEPS = 20480
SLURM_TRAINING = (f"learner.total_steps={SLURM_STEPS}", f"learner.eps_steps={SLURM_STEPS}", "eval.val_every=0",
                  "logging.checkpoint_every=256", "logging.log_every=256")
# A 2-minute limit with the signal 55 s before it: slurmctld checks limits every 30 s and sends the
# signal up to one check early, so it comes 35-65 s into every attempt (one job start is 8-15 s of
# imports): a first attempt trains at most ~57 s, less than 20,480 steps below 350 steps/s (60-135
# measured here under load; an idle CI machine is faster, hence twice the steps first chosen), and
# at 60 steps/s the training ends in its 7th attempt. Each requeue costs one of max_num_timeout; the
# job waiting for the training is requeued too.
SLURM_LIMITS = ("hydra.launcher.timeout_min=2", "hydra.launcher.signal_delay_s=55", "hydra.launcher.max_num_timeout=15",
                "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=2", "hydra.launcher.array_parallelism=2")


@pytest.fixture(scope="module")
def store_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """One PostgreSQL-backed MLflow server for both engines (each logs to its own experiment)."""
    with postgres_cluster() as postgres, mlflow_server_on(postgres, tmp_path_factory.mktemp("server")) as url:
        yield url


def launch(cwd: Path, args: tuple[str, ...], env: dict[str, str], timeout: float) -> str:
    """Run the sweep in its own process group (killed whole on a timeout); returns its output."""
    sweep = subprocess.Popen([sys.executable, "-m", "hgm_repro", *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        output, _ = sweep.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(sweep.pid, signal.SIGKILL)
        output, _ = sweep.communicate()
        pytest.fail(f"the sweep did not end in {timeout:.0f} s:\n{output[-5000:]}")
    finally:
        if sweep.poll() is None:  # interrupted (Ctrl-C): the cluster's own teardown cancels its jobs
            os.killpg(sweep.pid, signal.SIGKILL)
    assert sweep.returncode == 0, output[-5000:]
    return output


def check_store(url: str, experiment_name: str, launch_dir: Path, total_steps: int) -> list:
    """One FINISHED training per key, one FINISHED evaluation per cell, all under the sweep's parent
    run, nothing left RUNNING, each training metric step logged once, final.pt at the full step count."""
    from mlflow.tracking import MlflowClient

    from hgm_repro.contracts.checkpoint import load_checkpoint

    client = MlflowClient(tracking_uri=url)
    experiment = client.get_experiment_by_name(experiment_name)
    runs = client.search_runs([experiment.experiment_id], max_results=1000)
    assert [r.info.run_name for r in runs if r.info.status == "RUNNING"] == []
    (parent,) = [r for r in runs if r.data.tags.get("sweep") == "true"]
    assert parent.info.status == "FINISHED"
    staged = [r for r in runs if r.data.tags.get("stage") in ("train", "eval")]
    assert {r.data.tags.get("mlflow.parentRunId") for r in staged} == {parent.info.run_id}
    finished = [r for r in staged if r.info.status == "FINISHED"]
    trainings = Counter(r.data.tags["train_key"] for r in finished if r.data.tags["stage"] == "train")
    assert len(trainings) == len(SEEDS) and set(trainings.values()) == {1}, trainings
    evaluations = Counter((r.data.tags["model"], r.data.tags["scenario"], r.data.tags["seed"])
                          for r in finished if r.data.tags["stage"] == "eval")
    assert set(evaluations) == CELLS and set(evaluations.values()) == {1}, evaluations
    train = [r for r in finished if r.data.tags["stage"] == "train"]
    for run in train:
        for key in run.data.metrics:
            steps = Counter(m.step for m in client.get_metric_history(run.info.run_id, key))
            assert [s for s, n in steps.items() if n > 1] == [], (run.info.run_id, key, steps)
        final = launch_dir / "checkpoints" / run.data.tags["train_key"] / "final.pt"
        assert load_checkpoint(final)["env_steps"] == total_steps
    return train


# --- SLURM ---------------------------------------------------------------------------------


@pytest.fixture
def slurm_cluster() -> Iterator[dict[str, str]]:
    """slurmctld + slurmd (+ munge, slurmdbd on MariaDB) on this machine; yields the environment for its commands."""
    if not shutil.which("slurmctld") or not shutil.which("slurmdbd"):
        pytest.fail("SLURM not installed: run .ci/integration.sh (bash .ci/slurm_cluster.sh install)")
    if os.geteuid() != 0:
        pytest.skip("a single-node SLURM cluster needs root (slurmd)")
    root = Path(tempfile.mkdtemp(prefix="hgm_slurm_"))
    started = subprocess.run(["bash", str(SLURM_SCRIPT), "start", str(root)], capture_output=True, text=True,
                             timeout=240)
    try:
        assert started.returncode == 0, started.stdout + started.stderr + logs_of(root)
        yield environment(SLURM_CONF=str(root / "slurm.conf"))
    finally:
        subprocess.run(["bash", str(SLURM_SCRIPT), "stop", str(root)], capture_output=True, timeout=240)
        shutil.rmtree(root, ignore_errors=True)


def logs_of(root: Path) -> str:
    return "".join(f"\n== {p.name}\n{p.read_text(errors='replace')[-2000:]}" for p in sorted(root.glob("*.log")))


# A task's job ends a moment after it writes its result, which is what the sweep waits for; slurmd then
# tells slurmctld, which tells slurmdbd: sacct can show the last attempt RUNNING for some seconds after
# the sweep returned (CI saw it once). States in which SLURM has not yet settled a task's attempt:
UNSETTLED_STATES = {"PENDING", "RUNNING", "COMPLETING", "CONFIGURING", "REQUEUED", "RESIZING", "SUSPENDED"}


def settled_accounting(array_id: str, env: dict[str, str], timeout: float = 120.0) -> str:
    """sacct's records of every attempt of the array's tasks, once each task's last attempt has ended
    (or, after `timeout` seconds, as they are then, for the assertions to report)."""
    deadline = time.monotonic() + timeout
    while True:
        accounting = subprocess.run(["sacct", "--duplicates", "--allocations", "--noheader", "--parsable2", "-j",
                                     array_id, "--format=JobID,State,Start,End,Elapsed,ExitCode"], env=env,
                                    capture_output=True, text=True, timeout=60, check=True).stdout
        records = (line.split("|") for line in accounting.strip().splitlines())
        last_state = {job_id: state for job_id, state, *_ in records}  # sacct lists attempts in order
        if (last_state and not set(last_state.values()) & UNSETTLED_STATES) or time.monotonic() > deadline:
            return accounting
        time.sleep(2)


def test_slurm_job_array_requeued_by_the_time_limit_signal_resumes(store_server: str,
                                                                  slurm_cluster: dict[str, str],
                                                                  tmp_path: Path) -> None:
    launch(tmp_path, (*GRID, *SLURM_TRAINING, f"hydra.sweep.dir={tmp_path / 'sweep'}", "launcher=slurm",
                      *SLURM_LIMITS, f"tracking.uri={store_server}", "tracking.experiment_name=slurm"),
           slurm_cluster, timeout=900)

    train = check_store(store_server, "slurm", tmp_path, SLURM_STEPS)
    submitit = tmp_path / "sweep" / ".submitit"
    logs = "\n".join(p.read_text(errors="replace") for p in sorted(submitit.rglob("*_log.*")))
    assert "job interrupted (interrupted by SIGUSR2)" in logs, logs[-5000:]
    assert "Requeued job" in logs, logs[-5000:]
    # A training resumed in its own run: the interrupted attempt's run was reopened, not replaced.
    assert any(int(r.data.tags.get("resumes", "0")) >= 1 for r in train), [r.data.tags for r in train]

    (array_id,) = {p.name.split("_")[0] for p in submitit.iterdir() if p.is_dir() and "_" in p.name}
    accounting = settled_accounting(array_id, slurm_cluster)
    print(f"sacct --duplicates --allocations -j {array_id}:\n{accounting}")
    records = [line.split("|") for line in accounting.strip().splitlines()]
    assert any(state == "REQUEUED" for _, state, *_ in records), accounting
    tasks = {job_id for job_id, *_ in records}
    assert len(tasks) == len(CELLS), accounting  # one array task per cell
    completed = {job_id for job_id, state, *_ in records if state == "COMPLETED"}
    assert completed == tasks, accounting


# --- Ray -------------------------------------------------------------------------------------


@pytest.fixture
def ray_cluster() -> Iterator[dict[str, str]]:
    """`ray start --head` on loopback, in a temp dir of its own; stopped (its processes only) at the end."""
    pytest.importorskip("hydra_plugins.hydra_ray_launcher", reason="the `ray` extra: pip install -e '.[ray]'")
    import psutil

    ray = str(Path(sys.executable).parent / "ray")
    root = Path(tempfile.mkdtemp(prefix="hgm_ray_"))  # short: Ray's unix sockets live below it
    port = free_port()
    started = subprocess.run(
        [ray, "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", f"--temp-dir={root}",
         "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats"],
        env=environment(), cwd=root, capture_output=True, text=True, timeout=180)  # its workers' cwd
    try:
        assert started.returncode == 0, started.stdout[-3000:] + started.stderr[-3000:]
        yield environment(RAY_ADDRESS=f"127.0.0.1:{port}")  # `address=auto` finds this cluster, not another
    finally:
        # `ray stop` would stop every Ray instance on the machine: stop the processes of this one
        # (their command lines name its temp dir) and the workers they started.
        ours = [p for p in psutil.process_iter(["cmdline"]) if str(root) in " ".join(p.info["cmdline"] or ())]
        tree = {p.pid: p for p in ours}
        for process in ours:
            try:
                tree.update({c.pid: c for c in process.children(recursive=True)})
            except psutil.NoSuchProcess:
                pass
        for process in tree.values():
            try:
                process.terminate()
            except psutil.NoSuchProcess:
                pass
        _, alive = psutil.wait_procs(list(tree.values()), timeout=10)
        for process in alive:
            process.kill()
        shutil.rmtree(root, ignore_errors=True)


def test_ray_cluster_runs_the_grid(store_server: str, ray_cluster: dict[str, str], tmp_path: Path) -> None:
    # A job makes its Hydra output dir relative to its worker's cwd (the `ray start` directory),
    # not the launching one's: an absolute sweep dir puts them where the launch can see them.
    output = launch(tmp_path, (*GRID, f"hydra.sweep.dir={tmp_path / 'sweep'}", "launcher=ray",
                               "hydra.launcher.ray.init.address=auto", "hydra.launcher.ray.remote.num_cpus=1",
                               f"tracking.uri={store_server}", "tracking.experiment_name=ray"),
                    ray_cluster, timeout=600)
    assert "Connecting to existing Ray cluster" in output, output[-3000:]
    check_store(store_server, "ray", tmp_path, total_steps=256)  # the smoke preset's length
    assert len(list((tmp_path / "sweep").glob("*/.hydra/hydra.yaml"))) == len(CELLS)
