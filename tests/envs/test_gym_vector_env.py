"""The Gymnasium VectorEnv over the batched simulator, checked against Gymnasium's own conventions."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.utils.env_match import check_environments_match
from gymnasium.vector import AutoresetMode, SyncVectorEnv, VectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.wrappers.vector import RecordEpisodeStatistics

import hgm_repro
from hgm_repro.envs import ENV_ID, HeterogeneousHighwayGymEnv, HeterogeneousHighwayVectorEnv

SMALL = {"height": 36, "width": 36, "frame_stack": 2}
SHORT = {"episode_seconds": 5.0}  # 10 decisions: many episode ends in a few steps


def kwargs_for(observation: str, **extra) -> dict:
    kw = {"observation": observation, "simulator_overrides": SHORT, **extra}
    if observation != "kinematics":
        kw["observation_overrides"] = SMALL
    return kw


def make_vec(num_envs: int, **kw) -> VectorEnv:
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", **kw)


def test_import_hgm_repro_registers_the_env_without_loading_torch():
    root = Path(hgm_repro.__file__).resolve().parents[1]
    code = ("import sys, gymnasium, hgm_repro; spec = gymnasium.spec(hgm_repro.envs.ENV_ID); "
            "assert spec.vector_entry_point, spec; assert 'torch' not in sys.modules, 'torch was imported'")
    subprocess.run([sys.executable, "-c", code], check=True, cwd="/", env={"PYTHONPATH": str(root)})


@pytest.mark.parametrize("observation", ["kinematics", "hgm", "camera", "coordinates"])
def test_make_vec_gives_a_batched_vector_env_with_the_single_envs_spaces(observation):
    envs = make_vec(4, **kwargs_for(observation))
    single = HeterogeneousHighwayGymEnv(**kwargs_for(observation))
    assert isinstance(envs, VectorEnv) and isinstance(envs.unwrapped, HeterogeneousHighwayVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.single_observation_space == single.observation_space
    assert envs.observation_space == batch_space(single.observation_space, 4)
    assert envs.action_space == batch_space(single.action_space, 4)
    obs, _ = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    obs, reward, terminated, truncated, _ = envs.step(envs.action_space.sample())
    assert envs.observation_space.contains(obs)
    assert reward.shape == terminated.shape == truncated.shape == (4,) and terminated.dtype == np.bool_


@pytest.mark.parametrize("observation", ["kinematics", "hgm", "camera", "coordinates"])
def test_one_batched_env_matches_gymnasiums_sync_vector_env_over_the_single_env(observation):
    """Observations, rewards, flags and the whole `info` (values, `_key` masks, dtypes) are what
    Gymnasium's own SyncVectorEnv makes of the single env, over several episode ends."""
    kw = kwargs_for(observation)
    check_environments_match(make_vec(1, **kw), SyncVectorEnv([lambda: HeterogeneousHighwayGymEnv(**kw)]),
                             num_steps=40, seed=3, info_comparison="equivalence")


def test_1000_steps_at_64_envs_with_next_step_autoreset(one_thread):
    envs = make_vec(64, **kwargs_for("kinematics"))
    n = envs.num_envs
    envs.action_space.seed(0)
    obs, info = envs.reset(seed=0)
    assert info["_decision"].all() and (info["decision"] == 0).all()
    steps = np.zeros(n, dtype=int)  # decisions since the episode started
    returns = np.zeros(n)
    ended = np.zeros(n, dtype=bool)
    episodes = 0
    for _ in range(1000):
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
        assert envs.observation_space.contains(obs)
        # The envs whose episode ended on the previous step were reset instead of stepped.
        assert not reward[ended].any() and not terminated[ended].any() and not truncated[ended].any()
        assert (info["decision"][ended] == 0).all()
        assert np.array_equal(info["_reward_terms"], ~ended) and np.array_equal(info["_collision"], ~ended)
        steps = np.where(ended, 0, steps + 1)
        returns = np.where(ended, 0.0, returns + reward)
        assert np.array_equal(info["decision"], steps)
        assert np.array_equal(truncated, (steps == 10) & ~terminated)
        done = terminated | truncated
        if done.any():
            metrics = info["episode_metrics"]
            assert np.array_equal(info["_episode_metrics"], done)
            assert np.array_equal(metrics["decisions"][done], steps[done])
            np.testing.assert_allclose(metrics["episode_return"][done], returns[done], rtol=1e-4, atol=1e-3)
            assert (metrics["collisions"][done] == terminated[done]).all()
        else:
            assert "episode_metrics" not in info
        episodes += int(done.sum())
        ended = done
    assert episodes >= 64 * 1000 // 11  # every env ran its 10-decision episodes back to back


def test_autoreset_refills_the_frame_stacks_of_the_restarting_envs():
    envs = make_vec(8, **kwargs_for("hgm"))
    envs.reset(seed=1)
    ended = np.zeros(8, dtype=bool)
    restarted = 0
    for _ in range(25):
        obs, _, terminated, truncated, _ = envs.step(np.full(8, 4))
        for key in ("camera", "hgm"):  # [N, 3 * 2 frames, H, W]: a new episode starts with two equal frames
            first, second = obs[key][:, :3], obs[key][:, 3:]
            assert all(np.array_equal(first[i], second[i]) for i in np.flatnonzero(ended))
        restarted += int(ended.sum())
        ended = terminated | truncated
    assert restarted >= 8


def test_torch_arrays_hold_the_same_values_as_numpy():
    kw = kwargs_for("coordinates", seed=5)
    as_numpy, as_torch = make_vec(3, **kw), make_vec(3, array_type="torch", **kw)
    obs_n, info_n = as_numpy.reset()
    obs_t, info_t = as_torch.reset()
    assert isinstance(obs_t["coordinates"], torch.Tensor)
    assert data_equivalence(obs_n, {k: v.numpy() for k, v in obs_t.items()}, exact=True)
    rng = np.random.default_rng(0)
    for _ in range(12):
        actions = rng.integers(0, 5, 3)
        out_n = as_numpy.step(actions)
        out_t = as_torch.step(torch.as_tensor(actions))
        assert isinstance(out_t[1], torch.Tensor) and isinstance(out_t[4]["speed_kmh"], torch.Tensor)
        assert np.array_equal(out_n[0]["coordinates"], out_t[0]["coordinates"].numpy())
        assert np.allclose(out_n[1], out_t[1].numpy()) and np.array_equal(out_n[2], out_t[2].numpy())
        assert np.array_equal(out_n[4]["_speed_kmh"], out_t[4]["_speed_kmh"].numpy())


def test_reset_mask_restarts_only_those_envs():
    envs = make_vec(4, **kwargs_for("kinematics"))
    envs.reset(seed=0)
    for _ in range(3):
        before, *_ = envs.step(np.full(4, 4))
    mask = np.array([True, False, True, False])
    obs, info = envs.reset(options={"reset_mask": mask})
    assert np.array_equal(info["_decision"], mask) and (info["decision"][mask] == 0).all()
    assert np.array_equal(obs[~mask], before[~mask])
    _, _, _, _, info = envs.step(np.full(4, 4))
    assert np.array_equal(info["decision"], [1, 4, 1, 4])


def test_bad_arguments_fail_clearly():
    with pytest.raises(ValueError, match="array_type"):
        HeterogeneousHighwayVectorEnv(2, observation="kinematics", array_type="jax")
    with pytest.raises(ValueError, match="observation"):
        HeterogeneousHighwayVectorEnv(2, observation="lidar")
    envs = HeterogeneousHighwayVectorEnv(2, observation="kinematics")
    with pytest.raises(ValueError, match="one int"):
        envs.reset(seed=[1, 2])
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="actions"):
        envs.step(np.array([0, 5]))
    with pytest.raises(ValueError, match="actions"):
        envs.step(np.array([0]))


def test_a_gymnasium_dqn_loop_trains_on_it_with_record_episode_statistics(one_thread):
    """A few hundred steps of a minimal CleanRL-style DQN over Gymnasium's vector wrappers: the
    wrapper's episode statistics agree with the env's own episode metrics, and the Q-network learns
    (its TD loss on a fixed batch drops)."""
    envs = RecordEpisodeStatistics(make_vec(8, **kwargs_for("kinematics")))
    n, n_actions = envs.num_envs, envs.single_action_space.n
    obs_dim = int(np.prod(envs.single_observation_space.shape))
    torch.manual_seed(0)
    q = torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(obs_dim, 64), torch.nn.ReLU(),
                            torch.nn.Linear(64, n_actions))
    optimizer = torch.optim.Adam(q.parameters(), lr=1e-3)
    rng = np.random.default_rng(0)
    buffer: list[tuple] = []
    obs, _ = envs.reset(seed=0)
    ended = np.zeros(n, dtype=bool)
    episodes = 0

    def td_loss(batch: list[tuple], target_q: torch.nn.Module | None = None) -> torch.Tensor:
        o, a, r, o2, term = (torch.as_tensor(np.stack(x)) for x in zip(*batch, strict=True))
        with torch.no_grad():
            target = r.float() + 0.9 * (target_q or q)(o2).max(1).values * (~term).float()
        return torch.nn.functional.mse_loss(q(o).gather(1, a.long().unsqueeze(1)).squeeze(1), target)

    for step in range(300):
        eps = max(0.05, 1.0 - step / 200)
        with torch.no_grad():
            greedy = q(torch.as_tensor(obs)).argmax(1).numpy()
        actions = np.where(rng.random(n) < eps, rng.integers(0, n_actions, n), greedy)
        next_obs, reward, terminated, truncated, info = envs.step(actions)
        # Next-step autoreset: the transition from a final observation into a reset is no transition.
        buffer += [(obs[i], actions[i], reward[i], next_obs[i], terminated[i]) for i in np.flatnonzero(~ended)]
        if "episode" in info:
            done = info["_episode"]
            assert np.array_equal(done, info["_episode_metrics"])
            np.testing.assert_allclose(info["episode"]["r"][done], info["episode_metrics"]["episode_return"][done],
                                       rtol=1e-4, atol=1e-3)
            assert np.array_equal(info["episode"]["l"][done], info["episode_metrics"]["decisions"][done])
            episodes += int(done.sum())
        if step >= 50:
            batch = [buffer[i] for i in rng.integers(0, len(buffer), 64)]
            loss = td_loss(batch)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        obs, ended = next_obs, terminated | truncated
    assert episodes >= 8 * 300 // 11 and len(envs.return_queue) > 0
    # Against a frozen copy (DQN's target network) the targets stay put, so fitting them must lower
    # the loss; bootstrapping from the moving network itself need not.
    fixed = [buffer[i] for i in range(0, len(buffer), 7)]
    frozen = copy.deepcopy(q)
    before = td_loss(fixed, frozen).item()
    for _ in range(200):
        loss = td_loss(fixed, frozen)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    assert np.isfinite(before) and td_loss(fixed, frozen).item() < 0.9 * before
