"""Evaluation: every per-episode metric, for a learned model and for a non-learning host."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from hgm_repro.contracts.checkpoint import CheckpointMismatchError
from hgm_repro.contracts.config_files import scenario_config
from hgm_repro.contracts.events import CRASH_KINDS, EPISODE_EVENTS
from hgm_repro.evaluation import EPISODE_METRICS, evaluate
from hgm_repro.evaluation.episodes import episodes_per_env
from hgm_repro.learner import train
from hgm_repro.simulator import N_ACTIONS, Action
from tests.helpers.learner import Recorder, compose_job

MEANS = {f"eval/{k}" for k in EPISODE_METRICS}


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return train(compose_job(), tmp_path_factory.mktemp("eval"), Recorder())


def check_result(result, n_envs: int, per_env: int) -> None:
    assert list(result.episodes.columns) == ["env", "episode", *EPISODE_METRICS, *EPISODE_EVENTS]
    # The fair test: every env drives the same number of complete episodes, and only those count.
    assert len(result.episodes) == n_envs * per_env
    assert (result.episodes.groupby("env")["episode"].apply(list) == [list(range(per_env))] * n_envs).all()
    assert MEANS <= set(result.means)
    for key in EPISODE_METRICS:
        assert result.means[f"eval/{key}"] == pytest.approx(result.episodes[key].mean())
    assert result.decisions == result.episodes["decisions"].sum()
    assert (result.episodes["avg_speed_kmh"] > 0).all()
    # Every crash has exactly one kind: the kinds' rates add up to the collision rate.
    crash_rates = sum(result.means[f"eval/crashes_{k}"] for k in CRASH_KINDS)
    assert crash_rates == pytest.approx(result.means["eval/collisions"])


def test_budget_rounds_up_to_whole_episodes_per_env():
    assert episodes_per_env(200_000, 64, 240) == 14  # Table 4's budget: 896 complete episodes
    assert episodes_per_env(9_600, 16, 240) == 3
    assert episodes_per_env(8, 4, 20) == 1  # never less than one complete episode


def test_learned_model_greedy_evaluation(checkpoint):
    # smoke episodes last 10 s = 20 decisions: 120 decisions over 4 envs = 2 episodes per env.
    job = compose_job("eval.test_steps=120")
    result = evaluate(job, job.scenario, checkpoint)
    check_result(result, n_envs=4, per_env=2)
    assert (result.episodes["decisions"] <= 20).all()


def test_human_driven_host_evaluation():
    job = compose_job("model=human", "eval.test_steps=120")
    result = evaluate(job, scenario_config("1", job.simulator), None)  # scenario 1 (CV ratio 0)
    check_result(result, n_envs=4, per_env=2)
    assert result.means["eval/collisions"] == 0.0  # the human host keeps the NPC safety layer
    assert (result.episodes["decisions"] == 20).all()  # so every episode runs its full length


def test_a_host_given_to_the_test_drives_instead_of_the_jobs_model():
    """The human-driven job, driven by a host that brakes in every decision: the fair test is the same, the
    driving is the given host's: slower than the human-driven host, and it never changes lane."""
    job = compose_job("model=human", "eval.test_steps=120")
    brake = torch.nn.functional.one_hot(torch.full((4,), int(Action.DECELERATE)), N_ACTIONS)
    seen = []

    def host(env):
        seen.append(env.simulator.n_envs)
        return lambda td: td.set("action", brake)

    result = evaluate(job, job.scenario, None, host=host)
    check_result(result, n_envs=4, per_env=2)
    assert seen == [4]
    human = evaluate(job, job.scenario, None)
    assert result.means["eval/lane_changes"] == 0.0 < human.means["eval/lane_changes"]
    assert result.means["eval/avg_speed_kmh"] < human.means["eval/avg_speed_kmh"]


def test_a_tiny_budget_still_counts_only_complete_episodes():
    job = compose_job("model=human", "eval.test_steps=8")
    result = evaluate(job, job.scenario, None)
    check_result(result, n_envs=4, per_env=1)
    assert (result.episodes["decisions"] == 20).all()


def test_every_host_meets_the_same_initial_traffic(checkpoint):
    """Episode k of env e starts from the same traffic whoever drives, and whenever it starts."""
    from hgm_repro.envs import make_env
    from hgm_repro.evaluation.episodes import _traffic_seed

    states = []
    for model in ("human", "random"):
        job = compose_job(f"model={model}")
        env = make_env(job, job.scenario, n_envs=4, seed=0)
        env.simulator.generator.manual_seed(_traffic_seed(7, 0, 3))
        env.reset()
        states.append(env.simulator.state.pos_lon.clone())
        # A partial reset of env 2 with the same seed gives env 2 that same traffic again.
        env.simulator.generator.manual_seed(_traffic_seed(7, 0, 3))
        mask = torch.tensor([False, False, True, False])
        env.reset(TensorDict({"_reset": mask.unsqueeze(-1)}, batch_size=[4]))
        assert torch.equal(env.simulator.state.pos_lon[2], states[-1][2])
    assert torch.equal(states[0], states[1])


def test_evaluation_refuses_another_models_checkpoint(checkpoint):
    with pytest.raises(CheckpointMismatchError, match="'proposed'"):
        job = compose_job("model=min")
        evaluate(job, job.train_scenario, checkpoint)


def test_evaluation_accepts_other_test_settings(checkpoint):
    # Tested in another scenario with other test budgets: the same weights load.
    job = compose_job("eval.test_envs=2", "eval.test_steps=40", "learner.lr=0.5")
    result = evaluate(job, scenario_config("5", job.simulator), checkpoint)
    assert len(result.episodes) == 2 * episodes_per_env(40, 2, 20)


def test_an_episode_that_restarts_leaves_every_other_hosts_observation_as_it_was() -> None:
    """Where a crash in one env meets driving in the others: run_episodes restarts only the finished
    envs, and every host is handed its own current camera and HGM stacks at every decision (a partial
    TorchRL reset once handed the others all-zero observations, a blank frame each time any env
    restarted)."""
    from torch.nn import functional as F

    from hgm_repro.envs import make_env
    from hgm_repro.evaluation.episodes import run_episodes
    from hgm_repro.simulator import N_ACTIONS, Action

    job = compose_job("simulator.episode_seconds=8.0")
    env = make_env(job, job.train_scenario, n_envs=4, seed=7)
    keys = [k for k in env.observation_spec.keys() if k not in ("episode", "reward_terms")]
    seen = {"decisions": 0, "partial_restarts": 0}
    last_decisions = None

    def check_and_drive(td: TensorDict) -> TensorDict:
        nonlocal last_decisions
        stacks = env.observations.stacks
        for key in keys:  # what the host is handed is what its builder holds, every env, every decision
            assert torch.equal(td[key], stacks[key].stack), (key, seen)
            assert td[key].flatten(1).any(1).all(), key  # and never a blank observation
        decisions = env.simulator.state.decision.clone()
        if last_decisions is not None:
            restarted = decisions < last_decisions
            seen["partial_restarts"] += int(restarted.any() and not restarted.all())
        last_decisions = decisions
        seen["decisions"] += 1
        # Env 0 always accelerates (it rear-ends someone early); the others keep their speed.
        action = torch.full((4,), int(Action.NO_ACTION))
        action[0] = int(Action.ACCELERATE)
        return td.set("action", F.one_hot(action, N_ACTIONS))

    episodes = run_episodes(env, check_and_drive, 3, traffic=7)
    assert len(episodes) == 12 and episodes.loc[episodes.env == 0, "collisions"].sum() >= 1
    assert seen["partial_restarts"] >= 1  # the case under test happened: some envs restarted, not all
