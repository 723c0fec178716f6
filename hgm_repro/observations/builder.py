"""Builds the observations a model's streams ask for, stacked over time, from the simulator state.

Every stream is a pure function of `sim.state`; this class only picks the streams, encodes them
to the dtypes of docs/interfaces.md and keeps one frame stack per stream.
"""

from __future__ import annotations

import torch

from ..contracts.observation_config import ObservationConfig
from ..simulator import HighwaySimulator, TrafficState
from .birdseye_camera import birdseye_camera
from .coordinates import FEATURES, coordinates
from .frame_stack import FrameStack
from .front_camera import front_camera
from .hyper_grid_matrix import hyper_grid_matrix


class ObservationBuilder:
    """`frame()` -> single frames; `reset(mask)` / `step()` -> stacked observations, keys `cfg.keys`."""

    def __init__(self, sim: HighwaySimulator, obs_cfg: ObservationConfig):
        self.sim = sim
        self.cfg = obs_cfg
        self.keys = obs_cfg.keys
        self.stacks = {key: FrameStack(obs_cfg.frame_stack) for key in self.keys}

    def specs(self) -> dict[str, tuple[tuple[int, ...], torch.dtype]]:
        """key -> (shape without the batch dimension, dtype) of the stacked observations."""
        c = self.cfg
        f = c.frame_stack
        out: dict[str, tuple[tuple[int, ...], torch.dtype]] = {}
        if "camera" in self.keys:
            out["camera"] = ((3 * f, c.height, c.width), torch.uint8)
        if "hgm" in self.keys:
            out["hgm"] = ((3 * f, c.height, c.width), torch.uint8)
        if "coordinates" in self.keys:
            out["coordinates"] = ((f * c.coord_k * FEATURES,), torch.float32)
        return out

    @torch.no_grad()
    def frame(self, state: TrafficState | None = None) -> dict[str, torch.Tensor]:
        """One frame of every stream for `state` (default: the simulator's): camera/hgm uint8
        [N, 3, H, W], coordinates float32 [N, K*6]."""
        c, sim = self.cfg, self.sim
        s = sim.state if state is None else state
        out: dict[str, torch.Tensor] = {}
        if c.camera == "front":
            out["camera"] = front_camera(sim, s, height=c.height, width=c.width, fov_deg=c.camera_fov_deg,
                                         camera_height=c.camera_height, pitch_deg=c.camera_pitch_deg,
                                         vehicle_height=c.vehicle_height, max_range=c.camera_max_range)
        elif c.camera == "birdseye":
            out["camera"] = birdseye_camera(sim, s, height=c.height, width=c.width, v2x_range=c.v2x_range)
        if c.hgm != "none":
            out["hgm"] = hyper_grid_matrix(sim, s, height=c.height, width=c.width, v2x_range=c.v2x_range,
                                           variant=c.hgm, encoded=True, ahead=c.hgm_ahead,
                                           host_cell=c.hgm_host_cell)
        if c.coordinates:
            out["coordinates"] = coordinates(sim, s, k=c.coord_k, v2x_range=c.v2x_range)
        return out

    @torch.no_grad()
    def reset(self, mask: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """Stacked observations after `sim.reset(mask)`: the stacks of envs in `mask` (all when
        None) are refilled with the new first frame; other envs' stacks are left as they were.
        Only the reset envs are drawn: early in training most steps reset a few of N envs."""
        if mask is None or any(stack.stack is None for stack in self.stacks.values()):
            frames = self.frame()
            return {k: self.stacks[k].reset(frames[k]) for k in self.keys}
        rows = mask.to(self.sim.device).reshape(-1).nonzero().squeeze(1)
        if rows.numel() == 0:
            return {k: self.stacks[k].stack for k in self.keys}
        frames = self.frame(self.sim.state.select_envs(rows))
        return {k: self.stacks[k].refill(rows, frames[k]) for k in self.keys}

    @torch.no_grad()
    def step(self) -> dict[str, torch.Tensor]:
        """Stacked observations after `sim.step`: the newest frame is pushed onto every stack."""
        frames = self.frame()
        return {k: self.stacks[k].push(frames[k]) for k in self.keys}
