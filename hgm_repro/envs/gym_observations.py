"""What the Gymnasium envs observe: batched torch tensors for every env of the simulator, and the
Gymnasium space of one env.

Observations, chosen by name:
- "hgm", "camera", "coordinates": what the proposed method, Min's method and the Coordinate
  method see (the streams of conf/model/{proposed,min,coordinate}.yaml), built by
  `hgm_repro.observations.ObservationBuilder`, as a Dict space keyed like the TorchRL env;
- "kinematics": a small Box of the host and its nearest vehicles (ground truth, every vehicle,
  connected or not: a debugging and smoke-test view, not one of the paper's sensors).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from ..contracts.config_files import observation_config
from ..observations import ObservationBuilder
from ..simulator.highway import HighwaySimulator
from ..simulator.state import HOST

OBSERVATIONS = ("hgm", "camera", "coordinates", "kinematics")
# Which model's streams each observation name stands for.
_STREAMS_OF = {"hgm": "proposed", "camera": "min", "coordinates": "coordinate"}
KINEMATICS_FEATURES = ("present", "rel_lon", "rel_lat", "rel_speed", "lane")

Observation = torch.Tensor | dict[str, torch.Tensor]


@torch.no_grad()
def kinematics(sim: HighwaySimulator, vehicles: int, max_range: float) -> torch.Tensor:
    """float32 [N, vehicles + 1, 5]: per env, the host row (absolute: lateral position, speed,
    lane, each in [0, 1]), then the nearest active vehicles along the road within `max_range`,
    relative to the host, nearest first; rows of absent vehicles are zero."""
    s, c = sim.state, sim.config
    road_w = c.lanes * c.lane_width
    lane_span = max(c.lanes - 1, 1)
    dx = s.pos_lon - s.pos_lon[:, HOST:HOST + 1]
    visible = s.active & (dx.abs() < max_range)
    visible[:, HOST] = False
    dist = torch.where(visible, dx.abs(), torch.inf)
    k = min(vehicles, dist.shape[1])
    near = torch.topk(dist, k, dim=1, largest=False).indices

    def nearest(x: torch.Tensor) -> torch.Tensor:
        return x.gather(1, near)

    seen = nearest(visible).float()
    rows = torch.stack([
        seen,
        nearest(dx) / max_range,
        (nearest(s.pos_lat) - s.pos_lat[:, HOST:HOST + 1]) / road_w,
        (nearest(s.speed) - s.speed[:, HOST:HOST + 1]) / c.v_max,
        (nearest(s.target_lane) - s.target_lane[:, HOST:HOST + 1]).float() / lane_span,
    ], dim=2) * seen.unsqueeze(2)
    host = torch.stack([
        torch.ones_like(s.speed[:, HOST]), torch.zeros_like(s.speed[:, HOST]), s.pos_lat[:, HOST] / road_w,
        s.speed[:, HOST] / c.v_max, s.target_lane[:, HOST].float() / lane_span,
    ], dim=1)
    out = torch.zeros(s.pos_lon.shape[0], vehicles + 1, len(KINEMATICS_FEATURES), device=sim.device)
    out[:, 0] = host
    out[:, 1:k + 1] = rows
    return out.clamp(-1.0, 1.0)


def _box_for(shape: tuple[int, ...], dtype: torch.dtype) -> gym.spaces.Box:
    if dtype == torch.uint8:
        return gym.spaces.Box(0, 255, shape, np.uint8)
    return gym.spaces.Box(-np.inf, np.inf, shape, torch.empty(0, dtype=dtype).numpy().dtype)


class GymObservations:
    """The observation named `observation` of every env of `sim`: a dict of stacked streams (the
    paper's observations) or one kinematics tensor, each [N, ...] on the simulator's device.
    `single_space` is the Gymnasium space of one env's observation."""

    def __init__(self, sim: HighwaySimulator, observation: str, overrides: Mapping[str, Any] | None = None,
                 kinematics_vehicles: int = 15, kinematics_range: float = 100.0):
        if observation not in OBSERVATIONS:
            raise ValueError(f"observation={observation!r} is not allowed; choose one of {list(OBSERVATIONS)}")
        self.sim = sim
        self.name = observation
        self._k = int(kinematics_vehicles)
        self._range = float(kinematics_range)
        self.builder = None
        if observation == "kinematics":
            self.single_space: gym.Space = gym.spaces.Box(-1.0, 1.0, (self._k + 1, len(KINEMATICS_FEATURES)),
                                                          np.float32)
        else:
            self.builder = self._make_builder(observation, overrides)
            self.single_space = gym.spaces.Dict({k: _box_for(shape, dtype)
                                                 for k, (shape, dtype) in self.builder.specs().items()})

    def _make_builder(self, observation: str, overrides: Mapping[str, Any] | None) -> ObservationBuilder:
        return ObservationBuilder(self.sim, observation_config(_STREAMS_OF[observation], **dict(overrides or {})))

    def reset(self, mask: torch.Tensor | None = None) -> Observation:
        """After `sim.reset(mask)`: the envs in `mask` (all when None) start their frame stacks anew."""
        if self.builder is None:
            return kinematics(self.sim, self._k, self._range)
        return self.builder.reset(mask)

    def step(self, reset_mask: torch.Tensor | None = None) -> Observation:
        """After `sim.step` (and `sim.reset(reset_mask)` for the envs in `reset_mask`, whose stacks
        then start anew: the builder draws those envs' first frames only)."""
        if self.builder is None:
            return kinematics(self.sim, self._k, self._range)
        obs = self.builder.step()
        return obs if reset_mask is None else self.builder.reset(reset_mask)
