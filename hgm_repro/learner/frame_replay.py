"""A replay memory that stores each observation frame once (`runtime.replay_frames=true`).

A transition of the flat replay memory holds both observations, each a stack of F frames per
stream: 4F frames for two streams at F=2, although consecutive steps of an env share all but one.
Here every env keeps a ring of its own frames, one per env step, and a transition keeps only where
its frames are (`frame_env`, `frame_pos`, `episode_start`); the stacks of the observation and of
the n-step next observation are rebuilt at sampling, exactly as `FrameStack` built them (oldest
first; at an episode's start the first frame repeated). The quick preset's 320k transitions then
need about 2.5 GB instead of 10 GB.

Positions along an env's ring are consecutive within an episode. Two exceptions, both at episode
ends:
- time-up (truncated): the bootstrap reads the final observation, whose newest frame is not the
  next episode's first one, so it gets a position of its own (at most one per `episode_decisions`
  steps, which bounds the ring);
- crash (terminated): the target never reads the next observation ((1 - terminated) = 0), so it
  is not kept: such a transition's next observation is rebuilt as its window's last observation.

Sampling draws the same indices from the same PER sum tree as the flat memory, so a training with
either memory computes the same losses (a test pins the final weights).
"""

from __future__ import annotations

import math
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.data import TensorDictPrioritizedReplayBuffer

INDEX_KEYS = ("frame_env", "frame_pos", "episode_start")


class FrameReplay:
    """Wraps a TorchRL prioritized buffer of observation-free transitions with per-env frame rings."""

    def __init__(self, buffer: TensorDictPrioritizedReplayBuffer, obs_shapes: dict[str, tuple[int, ...]],
                 n_envs: int, frame_stack: int, n_step: int, episode_decisions: int, device: torch.device):
        self.buffer = buffer
        self.keys = tuple(obs_shapes)
        self.n_envs = n_envs
        self.frame_stack = frame_stack
        self.device = torch.device(device)
        # One frame of a stream: its stacked shape with the first (channel) dimension divided by F.
        self.frame_shapes = {k: (shape[0] // frame_stack, *shape[1:]) for k, shape in obs_shapes.items()}
        per_env = math.ceil(buffer.storage.max_size / n_envs)
        # Room for every transition still stored, the time-up frames among them, the older frames
        # of the oldest stack and the steps of the n-step windows not yet stored.
        self.ring = per_env + math.ceil(per_env / episode_decisions) + 1 + frame_stack + n_step + 2
        self.frames: dict[str, torch.Tensor] = {}
        self.pos = torch.zeros(n_envs, dtype=torch.long, device=self.device)  # next position to write
        self.start = torch.zeros(n_envs, dtype=torch.long, device=self.device)  # the episode's first frame

    @classmethod
    def for_env(cls, buffer: TensorDictPrioritizedReplayBuffer, env: Any, n_step: int,
                n_envs: int | None = None) -> FrameReplay:
        """The memory for `env` (a `HeterogeneousHighwayEnv`): its streams, envs, frame stack and episode
        length; `n_envs`: the envs of one training member when `env` holds a group's (default: all)."""
        builder = env.observations
        shapes = {k: shape for k, (shape, _) in builder.specs().items()}
        return cls(buffer, shapes, n_envs or env.batch_size[0], builder.cfg.frame_stack, n_step,
                   env.simulator.config.episode_decisions, env.device)

    def __len__(self) -> int:
        return len(self.buffer)

    def _newest(self, stack: torch.Tensor, key: str) -> torch.Tensor:
        return stack[:, stack.shape[1] - self.frame_shapes[key][0]:]

    def _write(self, key: str, rows: torch.Tensor, positions: torch.Tensor, frames: torch.Tensor) -> None:
        if key not in self.frames:
            self.frames[key] = torch.zeros(self.n_envs, self.ring, *self.frame_shapes[key], dtype=frames.dtype,
                                           device=self.device)
        self.frames[key][rows, positions % self.ring] = frames

    def observe(self, batch: TensorDictBase) -> TensorDictBase:
        """Keep the frames of `batch` ([envs, time] collected steps, in order) and return it without
        observations, with each step's frame index (`INDEX_KEYS`), ready for `NStepReturns`."""
        rows = torch.arange(self.n_envs, device=self.device)
        index = {k: torch.empty(batch.shape, dtype=torch.long, device=self.device) for k in INDEX_KEYS}
        for t in range(batch.shape[1]):
            step = batch[:, t]
            index["frame_env"][:, t], index["frame_pos"][:, t], index["episode_start"][:, t] = \
                rows, self.pos, self.start
            # The next observation's newest frame goes in now, one position on, so that a transition
            # is complete the moment it is stored (its successor step writes the same frame there
            # again, unless an episode ended: a reset frame then replaces a crash's last one).
            for key in self.keys:
                self._write(key, rows, self.pos, self._newest(step.get(key), key))
                self._write(key, rows, self.pos + 1, self._newest(step.get(("next", key)), key))
            # A time-up's final frame keeps its position: the next episode starts one further on.
            truncated = step.get(("next", "truncated")).reshape(-1) & ~step.get(("next", "terminated")).reshape(-1)
            self.pos = self.pos + 1 + truncated.long()
            self.start = torch.where(step.get(("next", "done")).reshape(-1), self.pos, self.start)
        out = batch.exclude(*self.keys, *[("next", k) for k in self.keys])
        for key, value in index.items():
            out.set(key, value)
        return out

    def restart(self) -> None:
        """Every env starts a new episode at its next frame (a resumed run restarts its traffic)."""
        self.start = self.pos.clone()

    def extend(self, transitions: TensorDictBase) -> None:
        self.buffer.extend(transitions)

    def stack(self, key: str, env: torch.Tensor, position: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        """[B, F*C, ...] stacks whose newest frame is at `position` of `env`'s ring, as `FrameStack` built them."""
        offsets = torch.arange(1 - self.frame_stack, 1, device=self.device)
        positions = torch.maximum(position.unsqueeze(1) + offsets, start.unsqueeze(1))
        frames = self.frames[key][env.unsqueeze(1), positions % self.ring]  # [B, F, C, ...]
        return frames.flatten(1, 2)

    def sample(self) -> TensorDictBase:
        """A prioritized batch with both observations rebuilt from the rings."""
        sample = self.buffer.sample()
        env, position, start = (sample.get(k).reshape(-1) for k in INDEX_KEYS)
        steps = sample.get("steps_to_next_obs", None)
        steps = torch.ones_like(position) if steps is None else steps.reshape(-1).long()
        crashed = sample.get(("next", "terminated")).reshape(-1).long()
        next_position = position + steps - crashed
        for key in self.keys:
            sample.set(key, self.stack(key, env, position, start))
            sample.set(("next", key), self.stack(key, env, next_position, start))
        return sample

    def update_priority(self, index: torch.Tensor, priority: torch.Tensor) -> None:
        self.buffer.update_priority(index, priority)

    def megabytes(self) -> float:
        frames = sum(t.numel() * t.element_size() for t in self.frames.values())
        stored = len(self.buffer) * self.buffer.storage[0].bytes() if len(self.buffer) else 0
        return (frames + stored) / 2**20

    def state_dict(self) -> dict[str, Any]:
        return {"buffer": self.buffer.state_dict(), "frames": dict(self.frames), "pos": self.pos, "start": self.start}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.buffer.load_state_dict(state["buffer"])
        self.frames = {k: v.to(self.device) for k, v in state["frames"].items()}
        self.pos, self.start = state["pos"].to(self.device), state["start"].to(self.device)
