"""The world of a batch of envs: a few tensors, one row per env, one column per vehicle slot.

Slot 0 is always the host vehicle (HV). Positions are in metres: `pos_lon` along the road
(absolute, increasing in the driving direction), `pos_lat` across it from the left road edge,
so lane k's centre is at (k + 0.5) * lane_width and lane 0 is the leftmost lane.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import IntEnum

import torch

HOST = 0


class Action(IntEnum):
    """The five high-level driving behaviours, in the paper's order (Vehicle Action Space)."""

    ACCELERATE = 0
    DECELERATE = 1
    LANE_LEFT = 2
    LANE_RIGHT = 3
    NO_ACTION = 4


N_ACTIONS = len(Action)


@dataclass
class TrafficState:
    # Vehicles, [N, M].
    pos_lon: torch.Tensor
    pos_lat: torch.Tensor
    speed: torch.Tensor
    cruise: torch.Tensor  # speed the driver means to hold: random actions move it, safety braking does not
    target_lane: torch.Tensor  # lane the vehicle is in, or changing into
    vtype: torch.Tensor  # index into SimulatorConfig.vehicle_types
    active: torch.Tensor  # False while a vehicle waits to respawn (it is then invisible)
    color: torch.Tensor  # [N, M, 3] uint8, random per vehicle: the camera never tells types apart
    was_ahead: torch.Tensor  # ahead of the host (by centre) after the last decision
    passed: torch.Tensor  # already overtaken by the host in this episode
    # Envs, [N].
    decision: torch.Tensor  # decisions taken in the current episode
    ep_speed_sum: torch.Tensor
    ep_lane_changes: torch.Tensor
    ep_overtakes: torch.Tensor
    ep_collisions: torch.Tensor
    ep_dangerous: torch.Tensor
    ep_distance: torch.Tensor
    ep_return: torch.Tensor
    # What the evaluation records per episode beyond the paper's metrics (`contracts.events`): where
    # the host's last lane change began, its lane-change requests and which of them the safety layer
    # refused, and what the episode's crash looked like (0/1 flags, set in the crash's decision).
    ep_last_lane_change: torch.Tensor  # decision index at which the host last began a lane change; -1 none
    ep_lane_change_requests: torch.Tensor
    ep_refused_gap: torch.Tensor
    ep_refused_parity: torch.Tensor
    ep_crash_into_leader: torch.Tensor
    ep_crash_from_behind: torch.Tensor
    ep_crash_partner_changing: torch.Tensor
    ep_crash_host_changing: torch.Tensor
    # Simulator health, accumulated since construction (never reset with an episode).
    npc_collisions: torch.Tensor
    npc_distance: torch.Tensor

    @property
    def n_envs(self) -> int:
        return self.pos_lon.shape[0]

    @property
    def n_vehicles(self) -> int:
        return self.pos_lon.shape[1]

    def tensors(self) -> dict[str, torch.Tensor]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def clone(self) -> TrafficState:
        return TrafficState(**{k: v.clone() for k, v in self.tensors().items()})

    def to(self, device: torch.device | str) -> TrafficState:
        return TrafficState(**{k: v.to(device) for k, v in self.tensors().items()})

    def select_envs(self, rows: torch.Tensor) -> TrafficState:
        """The rows of the envs in `rows` (LongTensor), e.g. to draw only the envs that were reset."""
        return TrafficState(**{k: v.index_select(0, rows) for k, v in self.tensors().items()})

    def select_env(self, index: int) -> TrafficState:
        """One env's rows (batch of 1), for rendering and debugging."""
        return TrafficState(**{k: v[index:index + 1] for k, v in self.tensors().items()})
