"""Pure-torch stand-ins for TorchRL's C++ segment trees, used only when the extension fails to load.

TorchRL's `PrioritizedSampler` keeps priorities in sum / min segment trees from its compiled
extension `torchrl._torchrl`. The torchrl 0.14.1 wheel's extension does not load against the
torch 2.13 CPU wheel this project pins (undefined C++ symbol), which leaves the sampler unusable.
Rather than replace the sampler (its alpha / beta / eps / max-priority logic and state_dict are
TorchRL's and stay in use), this module provides flat-tensor trees with the same methods and
installs them into TorchRL's sampler module when, and only when, the compiled ones are missing.

A flat tensor makes `query` and `scan_lower_bound` O(capacity) instead of O(log capacity); at
this project's replay sizes (10k to 100k) that is a few microseconds per minibatch.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import torch

log = logging.getLogger(__name__)


def _as_index(index: Any, device: torch.device) -> torch.Tensor | int:
    if isinstance(index, (int, np.integer)):
        return int(index)
    return torch.as_tensor(np.asarray(index) if isinstance(index, (list, np.ndarray)) else index,
                           device=device).long()


class _FlatTree:
    """Values in one float64 tensor; `reduce` defines what `query` returns over a range."""

    neutral: float = 0.0

    def __init__(self, capacity: int, device: torch.device | str | None = None):
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self._values = torch.full((int(capacity),), self.neutral, dtype=torch.float64, device=self.device)

    @property
    def size(self) -> int:
        return self._values.numel()

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, index: Any) -> torch.Tensor:
        return self._values[_as_index(index, self.device)].to(torch.float32)

    def __setitem__(self, index: Any, value: Any) -> None:
        index = _as_index(index, self.device)
        value = torch.as_tensor(value, dtype=torch.float64, device=self.device)
        self._values[index] = value

    def _range(self, left: Any, right: Any) -> torch.Tensor:
        return self._values[int(left):int(right)]

    def _result(self, value: torch.Tensor, like: Any) -> torch.Tensor | float:
        # The CPU sampler compares the result with Python numbers and feeds it to numpy.
        return value if isinstance(like, torch.Tensor) else float(value)


class SumTree(_FlatTree):
    neutral = 0.0

    def query(self, left: Any, right: Any) -> torch.Tensor | float:
        return self._result(self._range(left, right).sum(), left)

    def scan_lower_bound(self, mass: Any) -> torch.Tensor:
        """Smallest index whose prefix sum exceeds `mass` (skips zero-priority slots)."""
        mass = torch.as_tensor(np.asarray(mass) if not isinstance(mass, torch.Tensor) else mass,
                               dtype=torch.float64, device=self.device)
        index = torch.searchsorted(torch.cumsum(self._values, 0), mass, right=True)
        return index.clamp_max(self.size - 1)


class MinTree(_FlatTree):
    neutral = float("inf")

    def query(self, left: Any, right: Any) -> torch.Tensor | float:
        return self._result(self._range(left, right).min(), left)


def install_if_missing() -> bool:
    """Give TorchRL's PrioritizedSampler these trees when its compiled ones did not load."""
    from torchrl.data.replay_buffers.samplers import prioritized

    installed = False
    for precision in ("Fp32", "Fp64"):
        for prefix in ("", "Cuda"):
            for kind, cls in (("Sum", SumTree), ("Min", MinTree)):
                name = f"{prefix}{kind}SegmentTree{precision}"
                if getattr(prioritized, name, None) is None:
                    setattr(prioritized, name, cls)
                    installed = True
    if installed:
        log.info("torchrl's compiled segment trees are unavailable; using pure-torch priority trees")
    return installed
