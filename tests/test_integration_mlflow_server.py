"""A real MLflow tracking server on a real PostgreSQL database receives a smoke job.

Both servers are started here on loopback, in temporary directories, and stopped at the end.
Needs PostgreSQL's server binaries (initdb, pg_ctl) and psycopg2 for the MLflow server:
`.ci/integration.sh` installs them and runs `pytest -m integration`.
"""

from __future__ import annotations

import glob
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from hgm_repro.contracts.config_files import CONF_DIR

pytestmark = pytest.mark.integration
REPO_ROOT = CONF_DIR.parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def postgres_bin(name: str) -> str:
    # Debian's packages keep the server binaries off PATH, under /usr/lib/postgresql/<v>/bin.
    found = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}")) or [shutil.which(name) or ""]
    if not found[-1]:
        pytest.fail(f"PostgreSQL's {name} not found: run .ci/integration.sh (apt-get install -y postgresql)")
    return found[-1]


def as_postgres_user(cmd: list[str]) -> list[str]:
    """PostgreSQL refuses to run as root: drop to the `postgres` account when we are root."""
    return ["runuser", "-u", "postgres", "--", *cmd] if os.geteuid() == 0 else cmd


@contextmanager
def postgres_cluster() -> Iterator[str]:
    """A throwaway cluster on 127.0.0.1:<free port>; yields its SQLAlchemy URI."""
    root = Path(tempfile.mkdtemp(prefix="hgm_pg_"))  # under /tmp, reachable by the postgres user
    if os.geteuid() == 0:
        shutil.chown(root, "postgres", "postgres")
    data, port = root / "data", free_port()
    subprocess.run(as_postgres_user([postgres_bin("initdb"), "-D", str(data), "-U", "mlflow", "--auth=trust",
                                     "-E", "UTF8"]), check=True, capture_output=True, timeout=120)
    options = f"-p {port} -k {root} -c listen_addresses=127.0.0.1"
    subprocess.run(as_postgres_user([postgres_bin("pg_ctl"), "-D", str(data), "-o", options,
                                     "-l", str(root / "postgres.log"), "-w", "-t", "60", "start"]),
                   check=True, capture_output=True, timeout=120)
    try:
        # Name the driver: SQLAlchemy 2.1 defaults to psycopg 3, the `postgres` extra installs psycopg2.
        yield f"postgresql+psycopg2://mlflow@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run(as_postgres_user([postgres_bin("pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop"]),
                       capture_output=True, timeout=120)
        shutil.rmtree(root, ignore_errors=True)


@contextmanager
def mlflow_server_on(postgres: str, tmp_path: Path) -> Iterator[str]:
    """An MLflow server on 127.0.0.1:<free port> over `postgres`, its artifacts in `tmp_path`; yields its URL."""
    port = free_port()
    log = open(tmp_path / "mlflow_server.log", "w")  # noqa: SIM115 - closed below
    server = subprocess.Popen(
        [sys.executable, "-m", "mlflow", "server", "--backend-store-uri", postgres, "--host", "127.0.0.1",
         "--port", str(port), "--artifacts-destination", str(tmp_path / "server_artifacts"), "--workers", "1"],
        stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 180  # first start creates the schema in PostgreSQL
        while True:
            try:
                with urllib.request.urlopen(f"{url}/health", timeout=5) as answer:
                    if answer.status == 200:
                        break
            except OSError:
                pass
            if server.poll() is not None or time.monotonic() > deadline:
                log.flush()
                pytest.fail("MLflow server did not start:\n" + (tmp_path / "mlflow_server.log").read_text()[-3000:])
            time.sleep(1)
        yield url
    finally:
        stop_group(server)
        log.close()


@pytest.fixture
def postgres() -> Iterator[str]:
    with postgres_cluster() as uri:
        yield uri


@pytest.fixture
def mlflow_server(postgres: str, tmp_path: Path) -> Iterator[str]:
    with mlflow_server_on(postgres, tmp_path) as url:
        yield url


def stop_group(process: subprocess.Popen) -> None:
    """SIGTERM the server and the workers it started (its own session), SIGKILL if they linger."""
    for sig, wait in ((signal.SIGTERM, 30), (signal.SIGKILL, 10)):
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            pass
        try:
            process.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


def hgm(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "hgm_repro", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=900)


def test_jobs_log_to_a_remote_server_on_postgres(mlflow_server: str, tmp_path: Path) -> None:
    from mlflow.tracking import MlflowClient

    launch = tmp_path / "launch"
    launch.mkdir()
    for scenario in ("1", "5"):  # the second job reuses the first one's training through the server
        out = hgm(launch, "experiment=smoke", f"scenario={scenario}", f"tracking.uri={mlflow_server}")
        assert out.returncode == 0, out.stderr[-4000:]
    assert not (launch / "mlflow.db").exists()  # nothing went to the local default store

    client = MlflowClient(tracking_uri=mlflow_server)
    experiment = client.get_experiment_by_name("hgm_repro")
    every_run = client.search_runs([experiment.experiment_id], max_results=100)
    assert {r.info.status for r in every_run} == {"FINISHED"}
    # Each single job is a launch: a parent run (no stage tag) over the runs it made.
    launches = {r.info.run_id: r for r in every_run if r.data.tags.get("launch") == "job"}
    runs = [r for r in every_run if r.info.run_id not in launches]
    train = [r for r in runs if r.data.tags.get("stage") == "train"]
    evals = [r for r in runs if r.data.tags.get("stage") == "eval"]
    assert len(launches) == 2 and len(train) == 1 and len(evals) == 2 and len(runs) == 3
    assert {r.data.tags["mlflow.parentRunId"] for r in runs} == set(launches)
    for launch_run in launches.values():
        assert "stage" not in launch_run.data.tags and launch_run.data.tags["sweep"] == "false"
        (child,) = [r for r in evals if r.data.tags["mlflow.parentRunId"] == launch_run.info.run_id]
        scenario = child.data.tags["scenario"]
        assert launch_run.data.metrics == {}  # the launch's means are a table in its description
        assert f"| proposed | {scenario} | 1 | {child.data.metrics['eval/episode_return']:.4g} |" in \
            launch_run.data.tags["mlflow.note.content"]
    key = train[0].data.tags["train_key"]
    for run in runs:
        for tag in ("model", "scenario", "seed", "stage", "train_key", "git_commit", "git_dirty"):
            assert tag in run.data.tags, tag
        assert run.data.tags["train_key"] == key
    assert sorted(r.data.tags["training"] for r in evals) == ["reused", "trained"]
    assert sorted(r.data.tags["scenario"] for r in evals) == ["1", "5"]
    assert any(name.startswith("train/") for name in train[0].data.metrics)
    for name in ("eval/avg_speed_kmh", "eval/episode_return", "eval/collisions"):
        assert all(name in r.data.metrics for r in evals), name
    assert train[0].data.params["learner.total_steps"] == "256"
    # Artifacts went through the server; the checkpoint also stays in the launch dir.
    # (smoke validates every 128 steps, so the best network goes up beside the final one)
    assert [a.path for a in client.list_artifacts(train[0].info.run_id, "checkpoint")] == [
        "checkpoint/best.pt", "checkpoint/final.pt"]
    assert {"config.yaml", "episodes.csv"} <= {a.path for a in client.list_artifacts(evals[0].info.run_id)}
    assert (launch / "checkpoints" / key / "final.pt").is_file()
