"""SIGTERM as an exception that waits for the write in progress.

Schedulers (SLURM, Kubernetes, a user's `kill`) stop a job with SIGTERM. Turned into
`JobInterrupted` the job can close its MLflow runs as KILLED and leave its checkpoint
directory ready for a resume. A store write or a checkpoint save that is under way when
the signal lands finishes first: code wraps such writes in `protected()`.
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
    if _depth > 0:
        _pending = signum  # raised when the protected write ends
        return
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
        if _depth == 0 and _pending is not None:
            signum, _pending = _pending, None
            raise JobInterrupted(signum)


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within this block SIGTERM raises `JobInterrupted` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _on_signal)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
