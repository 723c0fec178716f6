"""The episode GIF an evaluation run carries: the job's host driving one episode of its scenario.

Glue between the job and `hgm_repro.envs.video.record_episode`: a non-learning host is its
driver; a learned host is the greedy policy of its checkpoint's network over the same
observation stacks the learner trained on.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import torch
from omegaconf import DictConfig

from ..envs.video import record_episode
from ..observations import ObservationBuilder, ObservationConfig
from ..simulator import HighwaySimulator
from ..simulator.loading import scenario_config, simulator_config
from .policies import attached_driver, trained_network

# Film a different episode than evaluation's first one, but the same one on every run of the job.
GIF_SEED_OFFSET = 7919


Policy = Callable[[HighwaySimulator], torch.Tensor]


def greedy_policy(cfg: DictConfig, checkpoint: Path, sim: HighwaySimulator) -> Policy:
    """`sim -> actions`: argmax of the trained network over stacked observations of `sim`."""
    net = trained_network(cfg, checkpoint, torch.device(cfg.device))
    builder = ObservationBuilder(sim, ObservationConfig.from_config(cfg.observation, cfg.model.streams))
    calls = 0

    @torch.no_grad()
    def act(sim_: HighwaySimulator) -> torch.Tensor:
        nonlocal calls
        # record_episode resets, then calls act once before every step: the first call sees the
        # fresh episode, every later one the state one step on.
        obs = builder.reset() if calls == 0 else builder.step()
        calls += 1
        return net(*(obs[k] for k in net.in_keys)).argmax(dim=-1)

    return act


def record_gif(cfg: DictConfig, checkpoint: Path | None, path: Path) -> Path:
    """Drive one episode of `cfg.scenario` with the job's host and save it as a GIF at `path`."""
    sim_cfg = simulator_config(cfg.simulator)
    sim = HighwaySimulator(sim_cfg, scenario_config(cfg.scenario, sim_cfg), n_envs=1,
                           device=str(cfg.device), seed=int(cfg.seed) + GIF_SEED_OFFSET)
    if cfg.model.learned:
        if checkpoint is None:
            raise ValueError(f"learned model {cfg.model.name!r} has no checkpoint to film")
        host = greedy_policy(cfg, checkpoint, sim)
    else:
        host = attached_driver(cfg, sim)
    record_episode(sim, host, path)
    return path
