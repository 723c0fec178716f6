"""Grouped training (`hgm_repro.learner.grouped`): members' traffic, update and results."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torch.func import stack_module_state

from hgm_repro.contracts.checkpoint import load_checkpoint
from hgm_repro.contracts.config_files import scenario_config, simulator_config
from hgm_repro.learner import train
from hgm_repro.learner.builders import make_loss
from hgm_repro.learner.grouped import _load_target_into, _stacked_loss, _update_inputs, check_group, train_group
from hgm_repro.models.builders import make_actor, make_network
from hgm_repro.simulator import HighwaySimulator
from tests.helpers.learner import Recorder, compose_job


def _trajectory(seeds: list[int], member_envs: int, steps: int, scenario: str = "train") -> list[torch.Tensor]:
    """Per step, the whole state flattened (positions, speeds, types, colours, activity) under a
    fixed action pattern that is the same in every member's block of envs."""
    cfg = simulator_config()
    sim = HighwaySimulator(cfg, scenario_config(scenario, cfg), member_envs * len(seeds), seed=seeds)
    actions = torch.arange(member_envs) % 5
    out = []
    for t in range(steps):
        result = sim.step(((actions + t) % 5).repeat(len(seeds)))
        if bool(result.done.any()):
            sim.reset(result.done)
        s = sim.state
        out.append(torch.cat([s.pos_lon, s.speed, s.vtype.float(), s.active.float(),
                              s.color.float().flatten(1)], 1))
    return out


@pytest.mark.parametrize("scenario", ["train", "5"])
def test_member_traffic_is_the_same_alone_and_in_a_group(scenario: str):
    steps, envs = 60, 3
    alone = _trajectory([7], envs, steps, scenario)
    group = _trajectory([3, 7, 11], envs, steps, scenario)
    for t in range(steps):
        torch.testing.assert_close(group[t][envs:2 * envs], alone[t], rtol=0, atol=0)
    # and the members do not share traffic
    assert not torch.equal(group[-1][:envs], group[-1][envs:2 * envs])


def test_group_of_seeds_needs_whole_blocks():
    cfg = simulator_config()
    with pytest.raises(ValueError, match=r"seed=\[1, 2\] is not allowed with n_envs=3"):
        HighwaySimulator(cfg, scenario_config("train", cfg), 3, seed=[1, 2])


# --- the stacked update and grouped training -------------------------------------------------------





def _random_batch(job, size: int, seed: int) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    obs_shape = (3 * job.observation.frame_stack, job.observation.height, job.observation.width)
    obs = {k: torch.randint(0, 256, (size, *obs_shape), generator=g, dtype=torch.uint8) for k in ("camera", "hgm")}
    nxt = {k: torch.randint(0, 256, (size, *obs_shape), generator=g, dtype=torch.uint8) for k in ("camera", "hgm")}
    action = torch.nn.functional.one_hot(torch.randint(0, 5, (size,), generator=g), 5).bool()
    terminated = torch.rand(size, 1, generator=g) < 0.3
    return TensorDict({**obs, "action": action, "priority_weight": torch.rand(size, generator=g) + 0.5,
                       "next": {**nxt, "reward": torch.randn(size, 1, generator=g), "terminated": terminated,
                                "done": terminated, "truncated": torch.zeros(size, 1, dtype=torch.bool)}},
                      batch_size=[size])


@pytest.mark.parametrize("double_dqn", [False, True])
def test_stacked_loss_is_each_members_dqn_loss(double_dqn: bool):
    """The vmapped loss of a group equals TorchRL's DQNLoss of each member on its own batch."""
    job = compose_job(f"learner.double_dqn={str(double_dqn).lower()}")
    torch.manual_seed(0)
    nets = [make_network(job) for _ in range(3)]
    losses = [make_loss(job.learner, make_actor(net)) for net in nets]
    for loss in losses:  # a target different from the online weights
        with torch.no_grad():
            for t in loss.target_value_network_params.values(True, True):
                t.add_(0.01 * torch.randn_like(t))
    batches = [_random_batch(job, 16, seed) for seed in range(3)]
    expected, expected_td = [], []
    for loss, batch in zip(losses, batches, strict=True):
        batch = batch.clone()
        expected.append(loss(batch)["loss"].detach())
        expected_td.append(batch["td_error"].reshape(-1))  # DQNLoss writes it into its input
    params, buffers = stack_module_state(nets)
    targets = []
    for net, loss in zip(nets, losses, strict=True):
        target = copy.deepcopy(net)
        _load_target_into(loss, net, target)
        targets.append(target)
    target_params = {k: v.detach() for k, v in stack_module_state(targets)[0].items()}
    base = copy.deepcopy(nets[0]).to("meta")
    fn = _stacked_loss(base, list(nets[0].in_keys), job.learner.gamma, double_dqn, job.learner.loss_function)
    loss, td_error = fn(params, buffers, target_params, _update_inputs(batches, list(nets[0].in_keys),
                                                                       "priority_weight"))
    torch.testing.assert_close(loss.detach(), torch.stack(expected), rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(td_error, torch.stack(expected_td), rtol=1e-5, atol=1e-5)


def test_group_members_must_differ_only_by_seed():
    with pytest.raises(ValueError, match="same training config except the seed"):
        check_group([compose_job("seed=0"), compose_job("seed=1", "learner.lr=0.001")])
    with pytest.raises(ValueError, match="distinct seeds"):
        check_group([compose_job("seed=0"), compose_job("seed=0")])


def _weights(path: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(path)["network"]


def test_grouped_training_gives_solo_checkpoints_and_repeats(tmp_path: Path):
    jobs = [compose_job(f"seed={s}") for s in (0, 1)]
    logs = [Recorder(), Recorder()]
    finals = train_group(jobs, [tmp_path / "a0", tmp_path / "a1"], logs)
    for job, final, log in zip(jobs, finals, logs, strict=True):
        state = load_checkpoint(final, job)  # its own train_key and config: refused otherwise
        assert state["finished"] and state["env_steps"] == job.learner.total_steps
        assert log.steps("train/loss") and log.steps("train/epsilon")[-1] == job.learner.total_steps
        # a solo `train` finds the member finished: the checkpoint is a solo one
        assert train(job, final.parent, Recorder()) == final
    first_layer = next(iter(_weights(finals[0])))
    assert not torch.equal(_weights(finals[0])[first_layer], _weights(finals[1])[first_layer])  # own weights
    again = train_group(jobs, [tmp_path / "b0", tmp_path / "b1"], [Recorder(), Recorder()])
    for first, second in zip(finals, again, strict=True):
        for name, value in _weights(first).items():
            torch.testing.assert_close(_weights(second)[name], value, rtol=0, atol=0)


def test_grouped_training_resumes_every_member(tmp_path: Path):
    jobs = [compose_job(f"seed={s}") for s in (0, 1)]
    dirs = [tmp_path / "m0", tmp_path / "m1"]
    # The log of member 1 raises after the checkpoint at step 64: a kill between two checkpoints.
    with pytest.raises(KeyboardInterrupt):
        train_group(jobs, dirs, [Recorder(), Recorder(stop_at=96)])
    for d in dirs:
        assert load_checkpoint(d / "last.pt")["env_steps"] == 64 and not (d / "final.pt").exists()
    logs = [Recorder(), Recorder()]
    finals = train_group(jobs, dirs, logs)
    for job, final, log in zip(jobs, finals, logs, strict=True):
        state = load_checkpoint(final, job)
        assert state["finished"] and state["env_steps"] == job.learner.total_steps
        assert log.calls[0][0] > 64  # picked up after the checkpoint, not from the start


def test_grouped_setting_changes_neither_train_key_nor_evaluation_key():
    from hgm_repro.contracts.train_key import evaluation_key, train_key

    solo, grouped = compose_job("learner.grouped=false"), compose_job("learner.grouped=true")
    assert train_key(solo) == train_key(grouped) and evaluation_key(solo) == evaluation_key(grouped)


def test_grouped_auto_means_cuda_only_and_bad_values_are_named():
    from hgm_repro.contracts.errors import ConfigError
    from hgm_repro.contracts.schema import validate
    from hgm_repro.learner.grouped import use_grouped
    from tests.helpers.learner import compose_cfg

    assert use_grouped("auto", "cuda:0") and not use_grouped("auto", "cpu")
    assert use_grouped(True, "cpu") and not use_grouped(False, "cuda")
    with pytest.raises(ConfigError, match=r"learner.grouped='maybe' is not allowed: expected one of 'auto'"):
        validate(compose_cfg("learner.grouped=maybe"))


def test_bf16_update_is_cuda_only_and_float32_keeps_the_keys():
    from hgm_repro.contracts.errors import ConfigError
    from hgm_repro.contracts.schema import validate
    from hgm_repro.contracts.train_key import evaluation_key, train_key
    from tests.helpers.learner import compose_cfg

    with pytest.raises(ConfigError, match=r"learner.update_dtype=bfloat16 is not allowed with device='cpu'"):
        validate(compose_cfg("learner.update_dtype=bfloat16"))
    # float32 is how every stored training ran: left out of both keys, so they stay what they were
    from omegaconf import open_dict

    cfg = compose_cfg()
    with open_dict(cfg):
        del cfg.learner["update_dtype"]
    before, now = validate(cfg), compose_job()
    assert train_key(before) == train_key(now) and evaluation_key(before) == evaluation_key(now)
    bf16 = compose_cfg("learner.update_dtype=bfloat16", "device=cuda")
    assert train_key(bf16) != train_key(now)  # a bf16 training is another training
