"""Test procedure: drive a fixed number of decisions in one scenario and report every episode.

A learned model runs its greedy policy (no exploration) from a checkpoint; a non-learning model
(`cfg.model.learned == false`: the human-driven host, IDM + MOBIL, random) drives the host
through its driver object. Both go through the same TorchRL env and the same loop, so their
metrics are computed identically: the env's per-episode `episode` outputs, read where `done`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import torch
from omegaconf import DictConfig
from tensordict import TensorDictBase
from torch.nn import functional as F
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ..envs import make_env
from ..experiment.interrupts import raise_if_pending
from ..metrics import EPISODE_METRICS
from ..simulator import N_ACTIONS, episode_metrics
from .policies import attached_driver, trained_network

# Test traffic is drawn from other seeds than training traffic (same model seed, other episodes),
# and the same for every model, so that methods meet the same traffic draws.
EVAL_SEED_OFFSET = 100_000


@dataclass
class EvaluationResult:
    """`episodes`: one row per episode (EPISODE_METRICS columns); `means`: `eval/<metric>` over rows.

    `partial` is True when no episode finished within the test budget: the rows are then the
    unfinished episodes so far, and their metrics cover fewer decisions than an episode.
    """

    episodes: pd.DataFrame
    means: dict[str, float] = field(default_factory=dict)
    partial: bool = False
    decisions: int = 0


Policy = Callable[[TensorDictBase], TensorDictBase]


def _learned_policy(cfg: DictConfig, checkpoint: Path | None, device: torch.device) -> Policy:
    from ..learner.builders import make_actor

    return make_actor(trained_network(cfg, checkpoint, device)).to(device)


def _driver_policy(cfg: DictConfig, env) -> Policy:
    driver = attached_driver(cfg, env.simulator)

    def policy(td: TensorDictBase) -> TensorDictBase:
        action = driver.act(env.simulator)
        return td.set("action", F.one_hot(action.long(), N_ACTIONS).to(env.device))

    return policy


def _unfinished_episodes(env) -> pd.DataFrame:
    """Metrics of the episodes in progress, by the simulator's own formulas."""
    rows = episode_metrics(env.simulator.state)
    return pd.DataFrame({k: rows[k].float().cpu().numpy() for k in EPISODE_METRICS})


@torch.no_grad()
def evaluate(cfg: DictConfig, scenario_node, checkpoint: Path | None) -> EvaluationResult:
    """Run `learner.test_steps` decisions (over `learner.test_envs` envs) in `scenario_node`'s traffic."""
    device = torch.device(cfg.device)
    if int(cfg.learner.get("torch_threads", 0)) > 0:
        torch.set_num_threads(int(cfg.learner.torch_threads))
    n_envs = int(cfg.learner.test_envs)
    env = make_env(cfg, scenario_node, n_envs=n_envs, seed=int(cfg.seed) + EVAL_SEED_OFFSET)
    if cfg.model.get("learned", True):
        policy = _learned_policy(cfg, checkpoint, device)
    else:
        policy = _driver_policy(cfg, env)

    rows: list[pd.DataFrame] = []
    iterations = math.ceil(int(cfg.learner.test_steps) / n_envs)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = env.reset()
        for _ in range(iterations):
            raise_if_pending()  # a SIGTERM stops the evaluation between steps
            td = policy(td)
            transition, td = env.step_and_maybe_reset(td)  # td: the next step's input (reset where done)
            done = transition["next", "done"].reshape(-1)
            if done.any():
                finished = transition["next", "episode"][done]
                rows.append(pd.DataFrame({k: finished[k].float().cpu().numpy() for k in EPISODE_METRICS}))

    partial = not rows
    if partial:
        warnings.warn(f"no episode finished in {iterations} decisions per env: reporting the unfinished ones "
                      f"(raise learner.test_steps)", stacklevel=2)
        rows.append(_unfinished_episodes(env))
    episodes = pd.concat(rows, ignore_index=True)
    means = {f"eval/{k}": float(episodes[k].mean()) for k in EPISODE_METRICS}
    means["eval/episodes"] = float(len(episodes))
    means["eval/partial"] = float(partial)
    env.close()
    return EvaluationResult(episodes=episodes, means=means, partial=partial, decisions=iterations * n_envs)
