"""Videos of a host driving: the episode GIF an evaluation run carries, and watching a trained agent.

Glue between the job (or `python -m hgm_repro.show`) and `hgm_repro.envs.video.record_episode`:
a non-learning host is its driver; a learned host is the greedy policy of its checkpoint's
network over the same observation stacks the learner trained on. With `panels`, each frame also
shows what the network saw (camera, HGM) and its Q-values beside the top-down view.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..contracts.names import GIF_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..envs.render import render_watch_frame
from ..envs.video import record_episode
from ..observations import ObservationBuilder
from ..observations.hyper_grid_matrix import hgm_geometry
from ..simulator import HighwaySimulator
from .policies import attached_driver, trained_network


class GreedyPolicy:
    """`sim -> actions`: argmax of the trained network over stacked observations of `sim`.

    Keeps what it last saw (`observation`) and computed (`action_values` [N, 5]) for the frame
    that shows the decision."""

    def __init__(self, job: JobConfig, checkpoint: Path, sim: HighwaySimulator) -> None:
        self.net = trained_network(job, checkpoint, torch.device(job.device))
        self.builder = ObservationBuilder(sim, job.observation)
        self.calls = 0
        self.observation: dict[str, torch.Tensor] = {}
        self.action_values = torch.empty(0)

    @torch.no_grad()
    def __call__(self, sim: HighwaySimulator) -> torch.Tensor:
        # record_episode resets, then calls the policy once before every step: the first call sees
        # the fresh episode, every later one the state one step on.
        self.observation = self.builder.reset() if self.calls == 0 else self.builder.step()
        self.calls += 1
        self.action_values = self.net(*(self.observation[k] for k in self.net.in_keys))
        return self.action_values.argmax(dim=-1)

    def render(self, sim: HighwaySimulator, env_index: int, action: int | None, caption: str | None) -> np.ndarray:
        """The frame of the state the policy just decided in (`record_episode`'s `render`)."""
        c = self.builder.cfg
        window = hgm_geometry(sim, c.height, c.width, c.v2x_range, c.hgm_ahead)
        return render_watch_frame(sim, env_index, self.observation, self.action_values[env_index].cpu().numpy(),
                                  action, caption, hgm_window=window)


def record_gif(job: JobConfig, checkpoint: Path | None, path: Path, seed: int | None = None,
               panels: bool = False, max_decisions: int | None = None) -> dict[str, float]:
    """Drive one episode of `job.scenario` with the job's host, save it at `path` (.gif or .mp4)
    and return the episode's metrics. The traffic comes from `seed` (default: the job's seed plus
    GIF_SEED_OFFSET). `panels` (learned hosts): every frame shows the network's inputs and Q-values."""
    seed = job.seed + GIF_SEED_OFFSET if seed is None else seed
    sim = HighwaySimulator(job.simulator, job.scenario, n_envs=1, device=job.device, seed=seed)
    render = None
    if job.model.learned:
        if checkpoint is None:
            raise ValueError(f"learned model {job.model.name!r} has no checkpoint to film")
        host = GreedyPolicy(job, checkpoint, sim)
        render = host.render if panels else None
    else:
        host = attached_driver(job, sim)
    return record_episode(sim, host, path, max_decisions=max_decisions, render=render)
