"""Collecting the next batch while the network learns from this one (`runtime.overlap`).

On a CPU the training loop alternates between two kinds of work that each keep one core busy: the
simulator and the observation builders stepping the envs, and the gradient updates. With
`overlap`, a second thread collects batch k + 1 while the loop stores batch k and learns from it;
torch releases the GIL inside its kernels, so the two run on two cores. The loop then waits for
the batch and goes on as before: logs, validation and checkpoints happen with the collector idle.

What it changes: batch k + 1 is collected by the policy as it stood before the updates of batch k
(one batch of lag: 16 env steps, 4 updates at the quick preset), acting with a copy of the online
network that the loop refreshes after each batch (the updates write the online weights in place, so
the acting thread must not read them). The exploration schedule steps before the next collection
starts, as without overlap.

Why a seed still fixes the run: the two threads share no state that timing could reorder. TorchRL
keeps its exploration mode (explore while collecting, greedy inside the loss) in one process-wide
variable; with two threads the loss's "greedy" would switch exploration off in the middle of a
collection now and then, so the overlapped loop keeps that mode per thread
(`per_thread_exploration_mode`). And the two threads draw from different generators. Collection draws
from the simulator's own generators and torch's (exploration, warm-up actions); the update thread
draws the replay samples from numpy's (TorchRL's prioritized sampler on CPU) and nothing from
torch's. Each generator therefore sees the same sequence of calls whatever the threads' timing.
"""

from __future__ import annotations

import copy
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import tensordict.nn.probabilistic as probabilistic
import torch
from tensordict import TensorDictBase


class _PerThreadMode(threading.local):
    """tensordict's interaction-mode holder (`get_mode` / `set_mode`), one value per thread."""

    mode: Any = None

    def get_mode(self) -> Any:
        return self.mode

    def set_mode(self, mode: Any) -> None:
        self.mode = mode


def per_thread_exploration_mode() -> None:
    """Make TorchRL's exploration mode (tensordict's interaction type) a per-thread setting, from
    now on in this process. Every `set_exploration_type` block sets and restores it in the thread
    it runs in, so a single-threaded program behaves exactly as before; the current thread keeps
    the mode it had."""
    if not isinstance(probabilistic._interaction_type, _PerThreadMode):
        current = probabilistic._interaction_type.get_mode()
        probabilistic._interaction_type = _PerThreadMode()
        probabilistic._interaction_type.set_mode(current)


class ActingCopies:
    """A copy of each member's online network for the collecting thread, refreshed between batches."""

    def __init__(self, nets: Sequence[torch.nn.Module]):
        self.online = list(nets)
        self.acting = [copy.deepcopy(net).requires_grad_(False) for net in nets]

    def refresh(self) -> None:
        with torch.no_grad():
            for acting, online in zip(self.acting, self.online, strict=True):
                for a, o in zip(acting.parameters(), online.parameters(), strict=True):
                    a.copy_(o)
                for a, o in zip(acting.buffers(), online.buffers(), strict=True):
                    a.copy_(o)


class Prefetcher:
    """`next(batches)` in one background thread, one batch ahead; `None` once the batches end."""

    def __init__(self, batches: Iterator[TensorDictBase]):
        per_thread_exploration_mode()
        self.batches = batches
        # torch's intra-op thread count is the calling thread's own (OpenMP): the collecting thread
        # takes the loop's, or it would spread its kernels over every core (and sum in another order).
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="collector",
                                       initializer=torch.set_num_threads, initargs=(torch.get_num_threads(),))
        self.pending: Future | None = None

    def start(self) -> None:
        self.pending = self.pool.submit(next, self.batches, None)

    def result(self) -> TensorDictBase | None:
        """The batch started last (waits for it); an error in the collecting thread is raised here."""
        pending, self.pending = self.pending, None
        return pending.result() if pending is not None else None

    def close(self) -> None:
        """Waits for a batch still being collected (the collector is shut down after it)."""
        if self.pending is not None:
            self.pending.exception()  # wait; a failure there no longer matters
            self.pending = None
        self.pool.shutdown(wait=True)
