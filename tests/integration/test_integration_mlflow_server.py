"""A real MLflow tracking server on a real PostgreSQL database receives a smoke job.

Both servers are started here on loopback, in temporary directories, and stopped at the end.
Needs PostgreSQL's server binaries (initdb, pg_ctl) and psycopg2 for the MLflow server:
`.ci/integration.sh` installs them and runs `pytest -m integration`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers.cli import hgm
from tests.helpers.servers import mlflow_server_on, postgres_cluster

pytestmark = pytest.mark.integration


@pytest.fixture
def postgres() -> Iterator[str]:
    with postgres_cluster() as uri:
        yield uri


@pytest.fixture
def mlflow_server(postgres: str, tmp_path: Path) -> Iterator[str]:
    with mlflow_server_on(postgres, tmp_path) as url:
        yield url


def test_jobs_log_to_a_remote_server_on_postgres(mlflow_server: str, tmp_path: Path) -> None:
    from mlflow.tracking import MlflowClient

    launch = tmp_path / "launch"
    launch.mkdir()
    for scenario in ("1", "5"):  # the second job reuses the first one's training through the server
        out = hgm(launch, "experiment=smoke", f"scenario={scenario}", f"tracking.uri={mlflow_server}", check=False)
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
