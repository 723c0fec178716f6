"""The learner's training reward: Table 2's reward unless a study re-weights the crash or rescales."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from hgm_repro.learner.training_reward import training_reward


def _steps() -> TensorDict:
    # Three env steps: plain driving, a crash (R_c = -20 inside the reward), a dangerous action.
    reward = torch.tensor([[1.5], [-19.0], [-1.0]])
    collision = torch.tensor([0.0, -20.0, 0.0])
    return TensorDict({"next": {"reward": reward, "reward_terms": {"collision": collision}}}, batch_size=[3])


def test_paper_setting_leaves_the_reward_as_it_is():
    steps = _steps()
    assert torch.equal(training_reward(steps, 1.0, 1.0), steps["next", "reward"])


def test_collision_weight_multiplies_only_the_crash_term():
    reward = training_reward(_steps(), reward_scale=1.0, collision_weight=5.0)
    assert reward.shape == (3, 1)
    assert torch.allclose(reward.squeeze(-1), torch.tensor([1.5, -99.0, -1.0]))


def test_reward_scale_applies_after_the_weight():
    reward = training_reward(_steps(), reward_scale=0.1, collision_weight=2.0)
    assert torch.allclose(reward.squeeze(-1), torch.tensor([0.15, -3.9, -0.1]))


def test_batched_time_windows_keep_their_shape():
    steps = _steps().reshape(3, 1)  # [envs, time] as the collector hands it over
    assert training_reward(steps, 1.0, 3.0).shape == (3, 1, 1)


@pytest.mark.parametrize("bad", ["learner.collision_weight=0", "learner.collision_weight=-2"])
def test_non_positive_collision_weight_is_refused(bad):
    from hgm_repro.contracts.errors import ConfigError
    from hgm_repro.contracts.schema import check_config
    from tests.helpers.learner import compose_cfg

    with pytest.raises(ConfigError, match="collision_weight"):
        check_config(compose_cfg(bad))


@pytest.mark.parametrize("grouped", [False, True], ids=["solo", "grouped"])
def test_training_with_a_weighted_crash_runs_to_the_end(tmp_path, grouped):
    from hgm_repro.contracts.checkpoint import load_checkpoint
    from hgm_repro.learner import train, train_group
    from tests.helpers.learner import compose_job

    jobs = [compose_job("learner.collision_weight=5", f"seed={s}") for s in (0, 1)]
    if grouped:
        finals = train_group(jobs, [tmp_path / "a", tmp_path / "b"], [lambda m, s: None] * 2)
    else:
        finals = [train(jobs[0], tmp_path / "a", lambda m, s: None)]
    assert all(load_checkpoint(f)["env_steps"] == 128 for f in finals)
