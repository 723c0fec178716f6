"""The learner options of the issue-20 study: two-phase epsilon, shaped random actions, Adam's eps,
Polyak target updates and the moving average of the weights. Each default trains as before."""

from __future__ import annotations

import copy

import pytest
import torch
from omegaconf import open_dict
from tensordict import TensorDict
from torchrl.objectives import HardUpdate, SoftUpdate

from hgm_repro.contracts.checkpoint import EMA_CHECKPOINT, load_checkpoint
from hgm_repro.contracts.errors import ConfigError
from hgm_repro.contracts.schema import check_config
from hgm_repro.contracts.train_key import train_key
from hgm_repro.learner import train
from hgm_repro.learner.builders import PolyakUpdate, make_loss, make_optimizer, make_target_updater
from hgm_repro.learner.exploration import LANE_CHANGES, EpsilonGreedy, random_action_probs
from hgm_repro.learner.member import update_ema
from hgm_repro.models.builders import make_actor, make_network
from hgm_repro.simulator import N_ACTIONS
from tests.helpers.learner import Recorder, compose_cfg, compose_job


def test_epsilon_falls_to_eps_end_then_to_the_floor():
    eps = EpsilonGreedy(1.0, 0.05, 160, eps_floor=0.01, floor_steps=320)
    seen = []
    for _ in range(40):
        eps.step(16)
        seen.append(float(eps.eps))
    assert seen[9] == pytest.approx(0.05, abs=1e-6)  # 160 steps: the first phase ends
    assert seen[19] == pytest.approx(0.03, abs=1e-6)  # half-way down the second phase
    assert seen[29] == pytest.approx(0.01, abs=1e-6) and seen[-1] == pytest.approx(0.01, abs=1e-6)
    assert seen == sorted(seen, reverse=True)


def test_without_a_second_phase_the_schedule_is_torchrls():
    from torchrl.data import OneHot
    from torchrl.modules import EGreedyModule

    ours, theirs = EpsilonGreedy(1.0, 0.05, 100), EGreedyModule(OneHot(N_ACTIONS), 1.0, 0.05, 100)
    for _ in range(10):
        ours.step(16)
        theirs.step(16)
        assert float(ours.eps) == float(theirs.eps)
    assert set(ours.state_dict()) == set(theirs.state_dict())  # checkpoints load either way


def test_a_floor_above_eps_end_is_refused():
    with pytest.raises(ValueError, match="eps_floor=0.2 is not allowed above eps_end=0.1"):
        EpsilonGreedy(1.0, 0.1, 100, eps_floor=0.2, floor_steps=10)
    with pytest.raises(ConfigError, match="learner.eps_floor=0.5 is not allowed above learner.eps_end"):
        check_config(compose_cfg("learner.eps_floor=0.5", "learner.eps_floor_steps=100"))


@pytest.mark.parametrize("share", [0.0, 0.1, 0.4, 1.0])
def test_random_actions_change_lanes_at_the_chosen_share(share):
    eps = EpsilonGreedy(1.0, 1.0, 1, lane_change_share=share)
    drawn = eps.random_actions(20_000, generator=torch.Generator().manual_seed(0))
    lane_changes = torch.isin(drawn, torch.tensor(LANE_CHANGES)).float().mean()
    assert float(lane_changes) == pytest.approx(share, abs=0.015)
    assert random_action_probs(share).sum() == pytest.approx(1.0)


def test_the_uniform_share_draws_what_randint_draws():
    eps = EpsilonGreedy(1.0, 1.0, 1)
    ours = eps.random_actions(100, generator=torch.Generator().manual_seed(3))
    assert torch.equal(ours, torch.randint(N_ACTIONS, (100,), generator=torch.Generator().manual_seed(3)))


def test_exploring_policy_keeps_the_lane_when_the_share_is_zero():
    eps = EpsilonGreedy(1.0, 1.0, 1, lane_change_share=0.0)
    greedy = torch.nn.functional.one_hot(torch.full((4096,), 2), N_ACTIONS)  # always "change left"
    out = eps(TensorDict(action=greedy.clone(), batch_size=[4096]))["action"].argmax(-1)
    assert not torch.isin(out, torch.tensor(LANE_CHANGES)).any()  # epsilon 1: every action random


def test_adam_eps_and_polyak_targets_come_from_the_config():
    job = compose_job("model=proposed", "learner.adam_eps=1.5e-4", "learner.target_tau=0.01")
    loss = make_loss(job.learner, make_actor(make_network(job)))
    assert make_optimizer(job.learner, loss.parameters()).defaults["eps"] == 1.5e-4
    updater = make_target_updater(job.learner, loss)
    assert isinstance(updater, SoftUpdate)
    online = dict(loss.value_network_params.flatten_keys().items())
    target = {k: v.clone() for k, v in loss.target_value_network_params.flatten_keys().items()}
    with torch.no_grad():
        for v in online.values():
            v.add_(1.0)
    updater.step()
    after = dict(loss.target_value_network_params.flatten_keys().items())
    for key, before in target.items():  # one step moves the target 1% of the way
        assert torch.allclose(after[key], before + 0.01 * (online[key] - before), atol=1e-6)
    hard = compose_job("model=proposed")
    assert isinstance(make_target_updater(hard.learner, make_loss(hard.learner, make_actor(make_network(hard)))),
                      HardUpdate)


def test_every_learner_value_is_part_of_the_train_key_and_has_one_default():
    """The key hashes the whole learner group: an option changes it, and a value the config does
    not give is refused by name (its default lives in conf/learner/dqn.yaml only)."""
    assert train_key(compose_job("learner.random_lane_change_share=0.1")) != train_key(compose_job())
    assert train_key(compose_job("learner.adam_eps=0.00015")) != train_key(compose_job())
    cfg = compose_cfg()
    with open_dict(cfg):
        del cfg.learner["target_tau"]
    with pytest.raises(ConfigError, match="learner.target_tau is missing: expected a number"):
        check_config(cfg)


def test_ema_training_keeps_ema_pt_and_validates_the_average(tmp_path):
    job = compose_job("learner.ema_decay=0.9", "eval.val_every=64", "eval.val_envs=2",
                      "learner.random_lane_change_share=0.1", "learner.eps_floor=0.01", "learner.eps_floor_steps=64",
                      "learner.eps_steps=32", "eval.checkpoint=ema")
    log = Recorder()
    final = train(job, tmp_path, log)
    ema = load_checkpoint(tmp_path / EMA_CHECKPOINT, job)
    last = load_checkpoint(final, job)
    assert ema["finished"] and ema.get("replay_buffer") is None and ema.get("optimizer") is None
    assert all(torch.equal(ema["network"][k], last["ema_network"][k]) for k in ema["network"])
    assert any(not torch.equal(ema["network"][k], last["network"][k]) for k in ema["network"])
    assert log.steps("val_ema/episode_return") == [64, 128] == log.steps("val/episode_return")
    assert last["epsilon"] == pytest.approx(0.01)
    with pytest.raises(ConfigError, match="eval.checkpoint=ema is not allowed with learner.ema_decay=0"):
        check_config(compose_cfg("eval.checkpoint=ema"))


def test_hgm_options_are_checked_and_change_the_train_key():
    assert train_key(compose_job("model=proposed", "observation.hgm_host_cell=own_range")) != \
        train_key(compose_job("model=proposed"))
    with pytest.raises(ConfigError, match="hgm_host_cell='corner' is not allowed; allowed: \\['paper', 'own_range'\\]"):
        check_config(compose_cfg("observation.hgm_host_cell=corner"))
    with pytest.raises(ConfigError, match="observation.hgm_ahead=-5 is not allowed"):
        check_config(compose_cfg("observation.hgm_ahead=-5"))


def test_polyak_targets_and_the_moving_average_match_the_per_tensor_forms_to_the_bit():
    # PolyakUpdate and update_ema gather their tensors once and lerp them in one call; they must
    # compute exactly what TorchRL's SoftUpdate and a per-tensor lerp_ compute, also after the
    # online weights were loaded from a checkpoint (in place) between steps.
    job = compose_job("model=proposed", "learner.target_tau=0.01")
    torch.manual_seed(0)
    net = make_network(job)
    twin = copy.deepcopy(net)
    fast_loss, slow_loss = (make_loss(job.learner, make_actor(n)) for n in (net, twin))
    fast, slow = make_target_updater(job.learner, fast_loss), SoftUpdate(slow_loss, tau=0.01)
    assert isinstance(fast, PolyakUpdate)
    ema_fast, ema_slow = copy.deepcopy(net), copy.deepcopy(net)
    for step in range(5):
        with torch.no_grad():
            for a, b in zip(net.parameters(), twin.parameters(), strict=True):
                noise = torch.randn_like(a)
                a.add_(noise)
                b.add_(noise)
        if step == 2:
            state = {k: v + 0.5 for k, v in net.state_dict().items()}
            net.load_state_dict(state)
            twin.load_state_dict(state)
        fast.step()
        slow.step()
        update_ema(ema_fast, net, 0.9)
        with torch.no_grad():
            for averaged, current in zip(ema_slow.parameters(), net.parameters(), strict=True):
                averaged.lerp_(current, 1.0 - 0.9)
    fast_targets = fast_loss.target_value_network_params.flatten_keys()
    slow_targets = slow_loss.target_value_network_params.flatten_keys()
    assert all(torch.equal(fast_targets[k], slow_targets[k]) for k in fast_targets.keys())
    assert not torch.equal(fast_targets[next(iter(fast_targets.keys()))],
                           fast_loss.value_network_params.flatten_keys()[next(iter(fast_targets.keys()))])
    assert all(torch.equal(a, b) for a, b in zip(ema_fast.parameters(), ema_slow.parameters(), strict=True))
