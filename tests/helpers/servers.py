"""Throwaway PostgreSQL and MLflow servers on loopback, in temporary directories, for the integration
tests: each is a context manager that stops its server at the end."""

from __future__ import annotations

import glob
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests.helpers import ui_check_script


def free_port() -> int:
    return ui_check_script().free_port()


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
        # The first start creates the schema in PostgreSQL: up to 3 minutes.
        if not ui_check_script().wait_healthy(url, server, timeout=180, poll_s=1):
            log.flush()
            pytest.fail("MLflow server did not start:\n" + (tmp_path / "mlflow_server.log").read_text()[-3000:])
        yield url
    finally:
        stop_group(server)
        log.close()


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

