"""After one real smoke job (training + evaluation, a subprocess like a user's launch): watching the
trained host, the network logged as an MLflow model, and the runs as the MLflow UI shows them."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from PIL import Image

from tests.helpers.cli import hgm


@pytest.fixture(scope="module")
def job(tmp_path_factory: pytest.TempPathFactory) -> SimpleNamespace:
    from mlflow.tracking import MlflowClient

    launch = tmp_path_factory.mktemp("launch").resolve()
    out = hgm(launch, "experiment=smoke", "scenario=3", "tracking.log_gif=false")
    client = MlflowClient(tracking_uri=f"sqlite:///{launch}/mlflow.db")
    experiment = client.get_experiment_by_name("hgm_repro")
    runs = client.search_runs([experiment.experiment_id])
    by_kind = {r.data.tags.get("stage") or r.data.tags.get("launch"): r for r in runs}
    assert len(runs) == 3 and set(by_kind) == {"train", "eval", "job"}
    return SimpleNamespace(launch=launch, log=out.stdout + out.stderr, client=client, experiment=experiment,
                           train=by_kind["train"], eval=by_kind["eval"], parent=by_kind["job"],
                           checkpoint=Path(by_kind["train"].data.tags["checkpoint_path"]))


def watch(job: SimpleNamespace, monkeypatch: pytest.MonkeyPatch, *args: str) -> Path:
    from hgm_repro.show import main

    monkeypatch.chdir(job.launch)  # the store is ./mlflow.db, as for the job
    return main(["scenario=3", "seed=0", "format=gif", f"out={job.launch / 'watch'}", *args])


def gif_frames(path: Path) -> list[Image.Image]:
    with Image.open(path) as gif:
        frames = []
        for i in range(gif.n_frames):
            gif.seek(i)
            frames.append(gif.convert("RGB"))
        return frames


# --- watching --------------------------------------------------------------------------------


def test_watch_a_training_run_writes_a_frame_per_state(job, monkeypatch) -> None:
    path = watch(job, monkeypatch, f"run_id={job.train.info.run_id}", "steps=5")
    assert path.suffix == ".gif" and path.stat().st_size > 0
    frames = gif_frames(path)
    assert len(frames) == 6  # the first state, then one per decision
    # Panels (camera, HGM, Q-values) above the top-down view: taller than the top-down view alone.
    assert frames[0].height > 300 and frames[0].width >= 1000


def test_watch_an_evaluation_run_or_a_checkpoint(job, monkeypatch) -> None:
    by_eval = watch(job, monkeypatch, f"run_id={job.eval.info.run_id}", "steps=2")
    assert len(gif_frames(by_eval)) == 3
    by_file = watch(job, monkeypatch, f"checkpoint={job.checkpoint}", "steps=2")
    assert len(gif_frames(by_file)) == 3
    assert by_file.name.startswith("watch_proposed_seed0_scenario3")


def test_watch_refuses_a_checkpoint_of_another_model(job, monkeypatch) -> None:
    with pytest.raises(SystemExit, match=r"is from another model: it was trained for model 'proposed'.*'min'"):
        watch(job, monkeypatch, f"checkpoint={job.checkpoint}", "model=min", "steps=2")


def test_watch_a_missing_run_or_file_fails_in_one_line(job, monkeypatch) -> None:
    with pytest.raises(SystemExit, match="no run 'not-a-run' in sqlite:///"):
        watch(job, monkeypatch, "run_id=not-a-run")
    with pytest.raises(SystemExit, match="no checkpoint at"):
        watch(job, monkeypatch, f"checkpoint={job.launch / 'nope.pt'}")
    with pytest.raises(SystemExit, match="do.*not apply to watching"):
        watch(job, monkeypatch, f"run_id={job.train.info.run_id}", "hgm=enriched")


def test_watch_checks_its_arguments_before_fetching_anything(tmp_path, monkeypatch) -> None:
    """`scenario=9` is refused before the store is opened or a checkpoint downloaded."""
    from hgm_repro.show import main

    monkeypatch.chdir(tmp_path)  # no store here: opening one would fail with another message
    with pytest.raises(SystemExit, match=r"no scenario '9'"):
        main(["run_id=abc", "scenario=9"])
    assert list(tmp_path.iterdir()) == []


# --- the network as an MLflow model ------------------------------------------------------------


def test_logged_model_gives_the_checkpoints_greedy_actions(job) -> None:
    import mlflow
    import mlflow.pytorch
    from omegaconf import OmegaConf

    from hgm_repro.contracts.config_files import scenario_config
    from hgm_repro.contracts.schema import check_config
    from hgm_repro.evaluation.policies import trained_network
    from hgm_repro.observations import ObservationBuilder
    from hgm_repro.simulator import HighwaySimulator

    mlflow.set_tracking_uri(f"sqlite:///{job.launch}/mlflow.db")
    logged = mlflow.pytorch.load_model(f"runs:/{job.train.info.run_id}/model")
    cfg = OmegaConf.load(job.client.download_artifacts(job.train.info.run_id, "config.yaml", str(job.launch)))
    typed = check_config(cfg)
    reference = trained_network(typed, job.checkpoint, torch.device("cpu"))

    sim = HighwaySimulator(typed.simulator, scenario_config("3", typed.simulator), n_envs=32, seed=5)
    builder = ObservationBuilder(sim, typed.observation)
    obs = builder.reset()
    for _ in range(3):
        sim.step(sim.npc_actions(sim.state)[:, 0])
        obs = builder.step()
    with torch.no_grad():
        inputs = [obs[k] for k in reference.in_keys]
        expected = reference(*inputs)
        got = logged(*inputs)
    assert type(logged) is type(reference) and not logged.training
    assert torch.equal(got.argmax(-1), expected.argmax(-1))
    torch.testing.assert_close(got, expected)


# --- the runs as the MLflow UI shows them -------------------------------------------------------


def test_run_names_put_what_differs_first(job) -> None:
    key = job.train.data.tags["train_key"]
    assert job.train.info.run_name == f"proposed seed0 training {key}"
    assert job.eval.info.run_name == "proposed seed0 scenario3 eval"
    assert job.parent.info.run_name == "job proposed seed0 scenario3"


def test_standard_tags_descriptions_and_nesting(job) -> None:
    for run in (job.train, job.eval, job.parent):
        tags = run.data.tags
        assert tags["mlflow.source.name"] == "python -m hgm_repro"
        assert tags["mlflow.user"] and tags["mlflow.source.type"] == "LOCAL"
        assert tags["mlflow.source.git.commit"] == tags["git_commit"] != "unknown"
        assert len(tags.get("mlflow.note.content", "")) > 40, run.info.run_name
    # A single job nests its runs under its own launch run, as a sweep nests under its parent.
    assert job.train.data.tags["mlflow.parentRunId"] == job.parent.info.run_id
    assert job.eval.data.tags["mlflow.parentRunId"] == job.parent.info.run_id
    assert "mlflow.parentRunId" not in job.parent.data.tags
    # The evaluation's description links to its training run.
    link = f"(#/experiments/{job.experiment.experiment_id}/runs/{job.train.info.run_id}?workflowType=machine_learning)"
    assert link in job.eval.data.tags["mlflow.note.content"]
    assert "mean episode return" in job.eval.data.tags["mlflow.note.content"]
    assert "Hyper-Grid Matrix" in job.experiment.tags["mlflow.note.content"]
    assert job.experiment.tags["mlflow.experimentKind"] == "custom_model_development"


def test_launch_run_summarises_its_evaluations(job) -> None:
    # A table in the description, no metrics: per-cell charts would bury the training curves.
    assert job.parent.data.metrics == {}
    means = job.eval.data.metrics
    assert (f"| proposed | 3 | 1 | {means['eval/episode_return']:.4g} | {means['eval/avg_speed_kmh']:.4g} |"
            in job.parent.data.tags["mlflow.note.content"])


def test_parameter_counts_are_params_and_values_are_tidy(job) -> None:
    assert int(job.train.data.params["params/total"]) > 0
    assert not any(k.startswith("params/") for k in job.train.data.metrics)
    for value in job.eval.data.metrics.values():
        assert value == float(f"{value:.6g}")  # no float32 tails such as 59.99999237


def test_job_log_gives_the_link_that_opens_the_runs(job) -> None:
    url = (f"http://127.0.0.1:5000/#/experiments/{job.experiment.experiment_id}/runs?workflowType=machine_learning"
           "&viewStateShareKey=grid")
    assert url in job.log and "compareRunsMode=CHART&viewStateShareKey=curves" in job.log
    assert "Pickle" not in job.log and "Initialized LazyTensorStorage" not in job.log  # no per-job noise
    assert f"mlflow ui --backend-store-uri sqlite:///{job.launch}/mlflow.db" in job.log
