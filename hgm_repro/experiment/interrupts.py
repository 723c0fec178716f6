"""SIGTERM as an exception, raised only at safe points.

Schedulers (SLURM, Kubernetes, a user's `kill`) stop a job with SIGTERM. Turned into
`JobInterrupted` the job can close its MLflow runs as KILLED and leave its checkpoint
directory ready for a resume. The handler only records the signal: raising from inside
arbitrary library code (a tensordict context manager, a store write) can leave that code in
a broken state or turn the interrupt into another error. Loops call `raise_if_pending()`
once per iteration (training batches, evaluation steps, waiting for a lock), and a
`protected()` block raises a pending signal when it ends.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType


class JobInterrupted(KeyboardInterrupt):
    """Raised in the main thread on SIGTERM. A KeyboardInterrupt, so `except Exception` passes it on."""

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum


_depth = 0
_pending: int | None = None


def _on_signal(signum: int, frame: FrameType | None) -> None:
    global _pending
    _pending = signum  # raised at the next safe point


def raise_if_pending() -> None:
    """Raise `JobInterrupted` if SIGTERM arrived since the last safe point (outside `protected()`)."""
    global _pending
    if _pending is not None and _depth == 0:
        signum, _pending = _pending, None
        raise JobInterrupted(signum)


@contextmanager
def protected() -> Iterator[None]:
    """Let the write inside finish before a pending SIGTERM is raised."""
    global _depth, _pending
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    raise_if_pending()


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within this block SIGTERM raises `JobInterrupted` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    global _pending
    previous = signal.signal(signal.SIGTERM, _on_signal)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        _pending = None  # a signal after the last safe point came when the work was already done
