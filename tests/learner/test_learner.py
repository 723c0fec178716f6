"""The Dueling DQN + PER learner: end to end on the smoke preset, checkpoints, resume, refusals."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from hgm_repro.contracts.checkpoint import CheckpointMismatchError, load_checkpoint
from hgm_repro.contracts.schema import JobConfig
from hgm_repro.learner import NonFiniteLossError, train
from hgm_repro.learner import member as member_module
from hgm_repro.learner.priority_trees import MinTree, SumTree
from tests.helpers.learner import Recorder, compose_job


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[JobConfig, Path, Recorder]:
    cfg = compose_job()
    log = Recorder()
    final = train(cfg, tmp_path_factory.mktemp("smoke"), log)
    return cfg, final, log


def test_smoke_training_runs_end_to_end_and_writes_checkpoints(trained):
    cfg, final, log = trained
    # A finished training keeps its full state once: final.pt supersedes last.pt.
    assert final.name == "final.pt" and final.exists() and not (final.parent / "last.pt").exists()
    state = load_checkpoint(final, cfg)
    assert state["finished"] and state["env_steps"] == 128
    assert state["updates"] == (128 - 32) // 4 + 1  # one update per 4 steps once 32 are stored
    assert state["epsilon"] == pytest.approx(cfg.learner.eps_end)
    assert state["beta"] == pytest.approx(1.0)
    assert {"network", "loss", "optimizer", "rng", "training_config", "replay_buffer"} <= set(state)


def test_training_logs_curves_only(trained):
    _, _, log = trained
    # Parameter counts are the job's params (tests/test_watch.py), not curves.
    assert not any(k.startswith("params/") for _, metrics in log.calls for k in metrics)
    for key in ("train/loss", "train/epsilon", "train/beta", "train/steps_per_s", "train/cpu_steps_per_s",
                "train/avg_speed_kmh", "train/lane_changes", "train/overtakes", "train/episode_return",
                "train/collisions"):
        assert log.steps(key), f"{key} never logged"
    assert log.steps("train/epsilon") == [32, 64, 96, 128]
    epsilons = [m["train/epsilon"] for _, m in log.calls if "train/epsilon" in m]
    assert epsilons == sorted(epsilons, reverse=True) and epsilons[0] < 1.0


def test_finished_run_returns_its_final_checkpoint(trained):
    cfg, final, _ = trained
    log = Recorder()
    assert train(cfg, final.parent, log) == final
    assert log.calls == []  # nothing trained again


def test_killed_run_resumes_from_last_and_stops_at_the_same_step(tmp_path):
    cfg = compose_job()
    with pytest.raises(KeyboardInterrupt):
        train(cfg, tmp_path, Recorder(stop_at=96))  # killed after the step-64 checkpoint
    assert not (tmp_path / "final.pt").exists()
    last = load_checkpoint(tmp_path / "last.pt", cfg)
    assert last["env_steps"] == 64 and not last["finished"]

    log = Recorder()
    final = train(cfg, tmp_path, log)
    state = load_checkpoint(final, cfg)
    assert state["env_steps"] == 128 and state["finished"]
    assert log.steps("train/epsilon") == [96, 128]  # continued from 64, did not start over
    # Epsilon continued its schedule instead of restarting at eps_start.
    assert log.calls[1][1]["train/epsilon"] < last["epsilon"]
    assert state["updates"] > last["updates"]


def test_checkpoint_from_another_model_is_refused(trained, tmp_path):
    _, final, _ = trained
    other = compose_job("model=min")
    with pytest.raises(CheckpointMismatchError, match=r"'proposed'.*'min'"):
        train(other, final.parent, Recorder())
    with pytest.raises(CheckpointMismatchError, match="learner.lr"):
        train(compose_job("learner.lr=0.1"), final.parent, Recorder())


def test_nan_loss_stops_the_run_and_keeps_checkpoints(tmp_path, monkeypatch):
    real = member_module.make_update

    def poisoned(*args, **kwargs):
        update = real(*args, **kwargs)

        def nan_update(batch):
            out = update(batch)
            out["loss"] = torch.tensor(float("nan"))
            return out

        return nan_update

    monkeypatch.setattr(member_module, "make_update", poisoned)
    cfg = compose_job("logging.checkpoint_every=16")
    log = Recorder()
    with pytest.raises(NonFiniteLossError, match="env step 32"):
        train(cfg, tmp_path, log)
    assert load_checkpoint(tmp_path / "last.pt", cfg)["env_steps"] == 16  # the last good one stays


def test_priority_trees_sample_in_proportion():
    sums, mins = SumTree(8), MinTree(8)
    values = torch.tensor([0.0, 1.0, 0.0, 3.0, 0.0, 0.0, 0.0, 4.0])
    sums[torch.arange(8)] = values
    mins[torch.arange(8)] = torch.where(values > 0, values, torch.tensor(float("inf")))
    assert sums.query(0, 8) == 8.0 and mins.query(0, 8) == 1.0
    index = sums.scan_lower_bound(torch.tensor([0.0, 0.99, 1.0, 3.9, 4.0, 7.99]))
    assert index.tolist() == [1, 1, 3, 3, 7, 7]  # never a zero-priority slot


def test_cuda_graph_is_ignored_with_a_warning_on_cpu():
    from hgm_repro.learner.builders import make_loss, make_update
    from hgm_repro.models.builders import make_actor, make_network

    job = compose_job("runtime.cuda_graph=true")
    loss = make_loss(job.learner, make_actor(make_network(job)))
    optimizer = torch.optim.Adam(loss.parameters(), lr=1e-3)
    with pytest.warns(UserWarning, match="cuda_graph"):
        update = make_update(job.learner, job.runtime, loss, optimizer, torch.device("cpu"))
    assert callable(update)


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("options", [[], ["runtime.cuda_graph=true"], ["runtime.compile=true"]],
                         ids=["eager", "cuda_graph", "compile"])
def test_smoke_training_on_cuda(tmp_path, options):
    cfg = compose_job("device=cuda", *options)
    state = load_checkpoint(train(cfg, tmp_path, Recorder()), cfg)
    assert state["env_steps"] == 128 and state["finished"]
