"""Evaluation: every per-episode metric, for a learned model and for a non-learning host."""

from __future__ import annotations

import pytest

from hgm_repro.evaluation import EPISODE_METRICS, evaluate
from hgm_repro.experiment.checkpoint import CheckpointMismatchError
from hgm_repro.learner import train

from .test_learner import Recorder, compose_cfg

MEANS = {f"eval/{k}" for k in EPISODE_METRICS}


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return train(compose_cfg(), tmp_path_factory.mktemp("eval"), Recorder())


def check_result(result, decisions: int) -> None:
    assert list(result.episodes.columns) == list(EPISODE_METRICS)
    assert len(result.episodes) >= 1
    assert MEANS <= set(result.means)
    for key in EPISODE_METRICS:
        assert result.means[f"eval/{key}"] == pytest.approx(result.episodes[key].mean())
    assert result.decisions == decisions
    assert (result.episodes["avg_speed_kmh"] > 0).all()


def test_learned_model_greedy_evaluation(checkpoint):
    # smoke episodes last 10 s = 20 decisions: 48 decisions over 4 envs (12 each) may finish none,
    # so give each env 30 decisions: crashed or timed-out episodes, both count.
    cfg = compose_cfg("learner.test_steps=120")
    result = evaluate(cfg, cfg.scenario, checkpoint)
    check_result(result, decisions=120)
    assert not result.partial
    assert (result.episodes["decisions"] <= 20).all()


def test_human_driven_host_evaluation():
    cfg = compose_cfg("model=human", "learner.test_steps=120")
    result = evaluate(cfg, "1", None)  # scenario 1 by name (CV ratio 0)
    check_result(result, decisions=120)
    assert result.means["eval/collisions"] == 0.0  # the human host keeps the NPC safety layer


def test_unfinished_episodes_are_reported_and_flagged(checkpoint):
    cfg = compose_cfg("model=human", "learner.test_steps=8")
    with pytest.warns(UserWarning, match="no episode finished"):
        result = evaluate(cfg, cfg.scenario, None)
    assert result.partial and result.means["eval/partial"] == 1.0
    assert len(result.episodes) == cfg.learner.test_envs
    assert (result.episodes["decisions"] == 2).all()


def test_evaluation_refuses_another_models_checkpoint(checkpoint):
    with pytest.raises(CheckpointMismatchError, match="'proposed'"):
        evaluate(compose_cfg("model=min"), "train", checkpoint)


def test_evaluation_accepts_other_test_settings(checkpoint):
    # Tested in another scenario with other test budgets: the same weights load.
    cfg = compose_cfg("learner.test_envs=2", "learner.test_steps=40", "learner.lr=0.5")
    result = evaluate(cfg, "5", checkpoint)
    assert result.decisions == 40
