"""The reward the learner builds its targets from: Algorithm 2's reward, optionally re-weighted.

Tests, validation and every reported return always score the paper's reward (Table 2); these
options change only what the learner learns from, and both default to the paper's (1.0), so that
the plain setting stays reachable and a study can say what a deviation buys.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase


def training_reward(step: TensorDictBase, reward_scale: float, collision_weight: float) -> torch.Tensor:
    """`("next", "reward")` of an env step (any batch shape) as the learner trains on it.

    collision_weight: the collision term R_c counts this many times (2.0 doubles the crash cost).
    reward_scale: then the whole reward is multiplied by it (rescaling targets, not preferences).
    """
    reward = step.get(("next", "reward"))
    if collision_weight != 1.0:
        # The env reports each of Algorithm 2's terms on its own (`reward_terms`, no trailing dim).
        collision = step.get(("next", "reward_terms", "collision")).unsqueeze(-1).to(reward.dtype)
        reward = reward + (collision_weight - 1.0) * collision
    return reward * reward_scale if reward_scale != 1.0 else reward
