"""The TorchRL env over the batched simulator."""

from __future__ import annotations

import pytest
import torch
from hydra import compose, initialize_config_dir
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.schema import JobConfig, check_config
from hgm_repro.envs import make_env
from hgm_repro.simulator import N_ACTIONS


def _cfg(*overrides: str) -> JobConfig:
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return check_config(compose("config", overrides=["experiment=smoke", *overrides]))


@pytest.mark.parametrize("model, keys", [
    ("proposed", {"camera", "hgm"}),
    ("min", {"camera"}),
    ("coordinate", {"camera", "coordinates"}),
    ("human", set()),
])
def test_specs_and_only_the_streams_the_model_reads(model, keys):
    cfg = _cfg(f"model={model}")
    env = make_env(cfg, cfg.train_scenario, n_envs=3, seed=0)
    check_env_specs(env)
    obs_keys = set(env.observation_spec.keys()) - {"episode", "reward_terms"}
    assert obs_keys == keys
    assert env.batch_size == torch.Size([3])


def test_partial_reset_only_touches_the_masked_envs():
    cfg = _cfg("model=proposed")
    env = make_env(cfg, cfg.train_scenario, n_envs=4, seed=0)
    td = env.reset()
    for _ in range(3):
        td["action"] = env.action_spec.rand()
        td = env.step(td)["next"]
    before = env.simulator.state.clone()
    mask = torch.tensor([True, False, True, False]).unsqueeze(-1)
    out = env.reset(TensorDict({"_reset": mask}, batch_size=[4]))
    after = env.simulator.state
    assert torch.equal(after.pos_lon[1], before.pos_lon[1]) and torch.equal(after.pos_lon[3], before.pos_lon[3])
    assert int(after.decision[0]) == 0 and int(after.decision[2]) == 0
    assert int(after.decision[1]) == 3
    # The reset envs' frame stacks hold only the new episode's first frame.
    f = cfg.observation.frame_stack
    cam = out["camera"][0].reshape(f, 3, *out["camera"].shape[-2:])
    assert all(torch.equal(cam[0], cam[k]) for k in range(1, f))


def test_episode_metrics_and_reward_terms_arrive_at_done():
    cfg = _cfg("model=proposed")
    env = make_env(cfg, cfg.train_scenario, n_envs=2, seed=1)
    decisions = cfg.simulator.episode_decisions
    no_action = torch.zeros(2, N_ACTIONS, dtype=torch.bool)
    no_action[:, 4] = True
    td = env.reset()
    rewards = []
    for _ in range(decisions):
        td["action"] = no_action
        out = env.step(td)
        nxt = out["next"]
        rewards.append(nxt["reward"].squeeze(-1))
        terms = sum(nxt["reward_terms", k] for k in nxt["reward_terms"].keys())
        assert torch.allclose(terms, nxt["reward"].squeeze(-1), atol=1e-5)
        if bool(nxt["done"].any()):
            break
        td = nxt
    done = nxt["done"].squeeze(-1)
    assert bool(done.any())
    ret = torch.stack(rewards).sum(0)
    assert torch.allclose(nxt["episode", "episode_return"][done], ret[done], atol=1e-3)
    assert bool((nxt["episode", "avg_speed_kmh"][done] >= 40 - 1e-3).all())
