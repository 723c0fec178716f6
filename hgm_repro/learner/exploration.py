"""Epsilon-greedy exploration with a second decay phase and a chosen share of random lane changes.

The paper anneals epsilon once and draws random actions uniformly (a lane change 2 times in 5).
On this highway a lane change takes 7 decisions and cannot be aborted, and the host has no safety
layer, so random lane changes are what crashes an otherwise careful host: an IDM lane keeper with
5% uniform random actions crashed in about 41% of its episodes, and in none when its random
actions kept the lane. Two options, both off by default (the paper's schedule and draw):

- `eps_floor` / `eps_floor_steps`: after reaching `eps_end` at `eps_steps`, epsilon keeps falling
  linearly to `eps_floor` over `eps_floor_steps` more env steps;
- `random_lane_change_share`: the probability that a random action is a lane change (left and
  right alike); the rest is spread evenly over accelerate, decelerate and no action. 0.4 is the
  uniform draw.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import OneHot
from torchrl.envs.utils import ExplorationType, exploration_type
from torchrl.modules import EGreedyModule

from ..simulator import N_ACTIONS, Action

LANE_CHANGES = (int(Action.LANE_LEFT), int(Action.LANE_RIGHT))
# The paper's uniform draw over the five actions gives lane changes this share.
UNIFORM_LANE_CHANGE_SHARE = len(LANE_CHANGES) / N_ACTIONS


def random_action_probs(lane_change_share: float) -> torch.Tensor:
    """[N_ACTIONS] probabilities of a random action: `lane_change_share` split over the two lane
    changes, the rest over the other actions."""
    probs = torch.full((N_ACTIONS,), (1.0 - lane_change_share) / (N_ACTIONS - len(LANE_CHANGES)))
    probs[list(LANE_CHANGES)] = lane_change_share / len(LANE_CHANGES)
    return probs


class EpsilonGreedy(EGreedyModule):
    """TorchRL's `EGreedyModule` (one-hot actions) with a second annealing phase and shaped random draws.

    The state dict is `EGreedyModule`'s: the phase is read off epsilon itself (above `eps_end`: the
    first phase; at or below: the second), so checkpoints of either kind load into the other.
    """

    def __init__(self, eps_init: float, eps_end: float, annealing_num_steps: int, *, eps_floor: float = 0.0,
                 floor_steps: int = 0, lane_change_share: float = UNIFORM_LANE_CHANGE_SHARE,
                 device: torch.device | str = "cpu"):
        super().__init__(OneHot(N_ACTIONS, device=device), eps_init=eps_init, eps_end=eps_end,
                         annealing_num_steps=annealing_num_steps, device=device)
        if floor_steps > 0 and eps_floor > eps_end:
            raise ValueError(f"eps_floor={eps_floor} is not allowed above eps_end={eps_end}: the second phase "
                             "only lowers epsilon")
        self.eps_floor = float(eps_floor)
        self.floor_steps = int(floor_steps)
        self.lane_change_share = float(lane_change_share)
        self.uniform = abs(self.lane_change_share - UNIFORM_LANE_CHANGE_SHARE) < 1e-12
        self.register_buffer("action_probs", random_action_probs(self.lane_change_share).to(device), persistent=False)

    def step(self, frames: int = 1) -> None:
        """Advance the schedule by `frames` env steps (call it every batch, as TorchRL's)."""
        if self.floor_steps == 0:
            super().step(frames)  # the paper's one phase, exactly as TorchRL computes it
            return
        eps, end = float(self.eps), float(self.eps_end)
        first_rate = (float(self.eps_init) - end) / self.annealing_num_steps
        second_rate = (end - self.eps_floor) / self.floor_steps
        for _ in range(frames):
            eps = max(end, eps - first_rate) if eps > end else max(self.eps_floor, eps - second_rate)
        self.eps.fill_(eps)

    def random_actions(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """[n] random action indices from the configured draw (the uniform draw is `torch.randint`'s, so
        that runs with the default settings draw exactly what they drew before the option existed)."""
        device = self.eps.device
        if self.uniform:
            return torch.randint(N_ACTIONS, (n,), generator=generator, device=device)
        return torch.multinomial(self.action_probs, n, replacement=True, generator=generator)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        if self.uniform or exploration_type() not in (ExplorationType.RANDOM, None):
            return super().forward(tensordict)
        action = tensordict.get(self.action_key)
        batch = action.shape[:-1]
        explore = torch.rand(batch, device=action.device) < self.eps
        drawn = self.random_actions(batch.numel()).reshape(batch)
        random_one_hot = torch.nn.functional.one_hot(drawn, N_ACTIONS).to(action.dtype)
        tensordict.set(self.action_key, torch.where(explore.unsqueeze(-1), random_one_hot, action))
        return tensordict
