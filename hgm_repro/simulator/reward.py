"""The paper's reward (Algorithm 2, Table 2): R = R_v + R_c + R_d + R_l + R_o, each term kept."""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch


def speed_reward(speed: torch.Tensor, v_min: float, v_max: float) -> torch.Tensor:
    """R_v = (1 + (v - v_min) / (v_max - v_min))^2 - 1: 0 at v_min, 1.25 halfway, 3 at v_max."""
    return (1.0 + (speed - v_min) / (v_max - v_min)) ** 2 - 1.0


@dataclass
class RewardTerms:
    speed: torch.Tensor
    collision: torch.Tensor
    dangerous: torch.Tensor
    lane_change: torch.Tensor
    overtake: torch.Tensor

    def total(self) -> torch.Tensor:
        return self.speed + self.collision + self.dangerous + self.lane_change + self.overtake

    def as_dict(self) -> dict[str, torch.Tensor]:
        return {f.name: getattr(self, f.name) for f in fields(self)}
