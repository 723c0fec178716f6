"""Test procedure: the same number of complete episodes in every test env, and every host meets
the same traffic (see `evaluate`); one row per episode.

A learned model runs its greedy policy (no exploration) from a checkpoint; a non-learning model
(`job.model.learned == false`: the human-driven host, IDM + MOBIL, random) drives the host
through its driver object. Both go through the same TorchRL env and the same loop, so their
metrics are computed identically: the env's per-episode `episode` outputs, read where `done`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import torch
from tensordict import TensorDict, TensorDictBase
from torch.nn import functional as F
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from ..contracts.events import RECORDED_PER_EPISODE, event_means
from ..contracts.interrupts import raise_if_pending
from ..contracts.names import EPISODE_METRICS, EVAL_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..envs import make_env
from ..simulator import N_ACTIONS, ScenarioConfig
from .policies import attached_driver, trained_network


@dataclass
class EvaluationResult:
    """`episodes`: one row per complete episode (`env`, `episode` within the env, then the
    EPISODE_METRICS and `contracts.events` columns); `means`: `eval/<metric>` over those rows (and the
    events' `eval/crashes_<kind>`, `eval/lane_change_requests`, `eval/refused_*_share`); `decisions`: the decisions
    the counted episodes drove."""

    episodes: pd.DataFrame
    means: dict[str, float] = field(default_factory=dict)
    decisions: int = 0


def episodes_per_env(test_steps: int, test_envs: int, episode_decisions: int) -> int:
    """The fair test's budget: every env drives this many complete episodes, so that the test
    covers at least `test_steps` decisions of full-length episodes (Table 4: 200,000)."""
    return max(1, math.ceil(test_steps / (test_envs * episode_decisions)))


def _traffic_seed(base: int, stream: int, index: int) -> int:
    """A seed per (test traffic, stream, index): stream 0 draws episode `index`'s initial traffic,
    stream 1 the NPCs' random actions at decision `index`."""
    return (base * 1_000_003 + stream * 1_000_000_007 + index * 7_919) % (2**63)


Policy = Callable[[TensorDictBase], TensorDictBase]


def learned_policy(job: JobConfig, checkpoint: Path | None, device: torch.device) -> Policy:
    """The greedy policy of `job.model`'s network with the weights of `checkpoint`, on `device`."""
    from ..models.builders import make_actor

    return make_actor(trained_network(job, checkpoint, device)).to(device)


def _driver_policy(job: JobConfig, env) -> Policy:
    driver = attached_driver(job, env.simulator)

    def policy(td: TensorDictBase) -> TensorDictBase:
        action = driver.act(env.simulator)
        return td.set("action", F.one_hot(action.long(), N_ACTIONS).to(env.device))

    return policy


@torch.no_grad()
def run_episodes(env, policy: Policy, episodes: int, traffic: int) -> pd.DataFrame:
    """Drive `policy` greedily until every env of `env` has finished `episodes` complete episodes;
    one row per counted episode (`env`, `episode`, then EPISODE_METRICS and the `contracts.events` records).

    Every host meets the same traffic for the same `traffic` seed: episode k of env e starts from
    the same initial traffic (its own seed per k, whenever the episode starts), and the NPCs'
    random actions at each decision come from a seed per decision. An env whose host crashed early
    starts its next episode earlier, so from its first crash on it meets other NPC draws. Envs that
    have finished their episodes keep driving uncounted (the batch keeps its shape)."""
    sim = env.simulator
    n_envs = sim.n_envs
    finished = torch.zeros(n_envs, dtype=torch.long, device=sim.device)
    rows: list[pd.DataFrame] = []
    decision = 0
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        sim.generator.manual_seed(_traffic_seed(traffic, 0, 0))
        td = env.reset()
        while bool((finished < episodes).any()):
            raise_if_pending()  # a stop signal ends the evaluation between steps
            td = policy(td)
            sim.generator.manual_seed(_traffic_seed(traffic, 1, decision))
            td = step_mdp(env.step(td), keep_other=True, exclude_action=True)
            decision += 1
            done = td["done"].reshape(-1)
            if not bool(done.any()):
                continue
            counted = done & (finished < episodes)
            if bool(counted.any()):
                metrics = td["episode"][counted]
                rows.append(pd.DataFrame({"env": torch.nonzero(counted).squeeze(1).cpu().numpy(),
                                          "episode": finished[counted].cpu().numpy(),
                                          **{k: metrics[k].float().cpu().numpy() for k in RECORDED_PER_EPISODE}}))
            finished = finished + done.long()
            # Episode k of an env always starts from seed k's traffic, whenever it starts.
            for k in finished[done].unique().tolist():
                sim.generator.manual_seed(_traffic_seed(traffic, 0, k))
                restart = done & (finished == k)
                reset = env.reset(TensorDict({"_reset": restart.unsqueeze(-1)}, batch_size=[n_envs], device=env.device))
                # Only the restarted envs' rows: TorchRL fills the rows it did not reset from the tensordict it
                # was given, which holds nothing but `_reset`, so they come back as zeros. Taken whole, every
                # other host would see one blank camera and HGM each time any env starts an episode.
                keys = [*env.observation_spec.keys(), "done", "terminated", "truncated"]
                td.update(td.select(*keys).where(~restart, reset.select(*keys)))
    return pd.concat(rows, ignore_index=True).sort_values(["env", "episode"], ignore_index=True)


def episode_means(episodes: pd.DataFrame, prefix: str) -> dict[str, float]:
    """`<prefix>/<metric>` means over the episodes, and `<prefix>/episodes`."""
    means = {f"{prefix}/{k}": float(episodes[k].mean()) for k in EPISODE_METRICS}
    means[f"{prefix}/episodes"] = float(len(episodes))
    return means


def evaluate(job: JobConfig, scenario: ScenarioConfig, checkpoint: Path | None,
             host: Callable[[object], Policy] | None = None) -> EvaluationResult:
    """The fair test in `scenario`'s traffic (usually `job.scenario`): each of `eval.test_envs` envs drives the same
    number of complete episodes (`episodes_per_env`, at least `eval.test_steps` decisions in
    all), only complete episodes count, and every model of a seed meets the same traffic
    (`run_episodes`). `host`, given the test env, makes the policy that drives instead of `job.model`'s
    (a probe's host, tested exactly as a model is)."""
    device = torch.device(job.device)
    if job.runtime.torch_threads > 0:
        torch.set_num_threads(job.runtime.torch_threads)
    n_envs = job.eval.test_envs
    traffic = job.seed + EVAL_SEED_OFFSET
    env = make_env(job, scenario, n_envs=n_envs, seed=traffic)
    if job.eval.host_safety_layer:
        # The probe: a learned host that trained without the layer, tested under it (validation refuses
        # the option for hosts that have a layer of their own).
        env.simulator.host_safety_layer = True
    if host is not None:
        policy = host(env)
    else:
        policy = learned_policy(job, checkpoint, device) if job.model.learned else _driver_policy(job, env)
    quota = episodes_per_env(job.eval.test_steps, n_envs, env.simulator.config.episode_decisions)
    episodes = run_episodes(env, policy, quota, traffic)
    env.close()
    means = {**episode_means(episodes, "eval"), **event_means(episodes, "eval")}
    return EvaluationResult(episodes=episodes, means=means, decisions=int(episodes["decisions"].sum()))
