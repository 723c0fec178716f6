"""n-step returns for transitions collected one decision at a time from every env.

TorchRL's `MultiStep` sums the discounted rewards of up to n steps (stopping at an episode end),
replaces ("next", obs) by the observation n steps later and writes `steps_to_next_obs`, which
`DQNLoss`'s TD(0) estimator reads to discount the bootstrap by gamma ** steps. Two things it does
not do that this wrapper adds:

- memory across batches: our collector yields one step per env per batch, so the last n - 1 steps
  of every env are kept and a transition leaves the window once its n-step future is known;
- the done flags of the window's last step. `MultiStep` shifts every ("next", ...) entry except
  the done flags, so a transition whose window runs into a crash keeps terminated = False and
  bootstraps from the crash state (checked on torchrl 0.14.1). Here ("next", done / terminated /
  truncated) are taken from the step at which the window ends.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data.postprocs import MultiStep

DONE_KEYS = ("done", "terminated", "truncated")


class NStepReturns:
    """Feed [envs, time] batches in order; get back the transitions whose n-step window is complete."""

    def __init__(self, n_steps: int, gamma: float):
        if n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {n_steps}")
        self.n_steps = n_steps
        self.multi_step = MultiStep(gamma=gamma, n_steps=n_steps)
        self._tail: TensorDictBase | None = None  # the last n - 1 steps of every env

    def __call__(self, batch: TensorDictBase) -> TensorDictBase | None:
        """`batch`: [envs, time]. Returns [envs, time'] transitions (time' may be 0), or None
        while fewer than n steps have been seen."""
        if self.n_steps == 1:
            return batch
        joined = batch if self._tail is None else torch.cat([self._tail, batch], dim=1)
        self._tail = joined[:, -(self.n_steps - 1):].clone()
        if joined.shape[1] < self.n_steps:
            return None
        out = self.multi_step(joined.clone(False))
        # Where each transition's window ends: t + steps_to_next_obs - 1 along time.
        end = torch.arange(joined.shape[1], device=joined.device).expand(joined.shape[0], -1) \
            + out.get("steps_to_next_obs").reshape(joined.shape[0], -1) - 1
        for key in DONE_KEYS:
            flag = joined.get(("next", key))
            index = end.reshape(*end.shape, *([1] * (flag.ndim - 2))).expand_as(flag)
            out.set(("next", key), flag.gather(1, index))
        # Only the first T - (n - 1) steps have their whole window inside `joined`.
        return out[:, : joined.shape[1] - (self.n_steps - 1)]

    def reset(self) -> None:
        """Forget the kept steps (a resumed run restarts its envs from fresh episodes)."""
        self._tail = None
