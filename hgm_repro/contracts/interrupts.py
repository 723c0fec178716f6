"""Stop signals as an exception, raised only at safe points.

Schedulers and users stop a job with a signal: SIGTERM (`kill`, `scancel`, Kubernetes), SIGINT
(Ctrl-C) or SIGUSR2 (SLURM's `--signal=USR2@...` before a time limit, which submitit answers by
requeueing the job). Turned into `JobInterrupted` the job can write `last.pt`, close its MLflow
runs as KILLED and leave its checkpoint directory ready for a resume. The handler only records
the signal: raising from inside arbitrary library code (a tensordict context manager, a store
write) can leave that code in a broken state or turn the interrupt into another error. Loops
call `raise_if_pending()` once per iteration (training batches, evaluation steps, waiting for a
lock), a `protected()` block raises a pending signal when it ends, and a `deferred()` block
leaves it to the next safe point (the learner's, which writes `last.pt` first).

Once the job has cleaned up, `hand_on` gives the signal to whoever handled it before the job
started: under submitit that is its requeue handler (SIGUSR2: checkpoint the callable, requeue,
exit), so the requeued job resumes from `last.pt`; otherwise the process exits with 128 + signal.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any, NoReturn

from filelock import Timeout

STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGUSR2)


class JobInterrupted(KeyboardInterrupt):
    """Raised in the main thread on a stop signal. A KeyboardInterrupt, so `except Exception` passes it on."""

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum


_depth = 0
_pending: int | None = None
_previous: dict[int, Any] = {}  # the handlers the job replaced, for `hand_on`


def _on_signal(signum: int, frame: FrameType | None) -> None:
    global _pending
    _pending = signum  # raised at the next safe point


def pending() -> bool:
    """A stop signal arrived and will be raised at the next safe point."""
    return _pending is not None and _depth == 0


def raise_if_pending() -> None:
    """Raise `JobInterrupted` if a stop signal arrived since the last safe point (outside `protected()`)."""
    global _pending
    if _pending is not None and _depth == 0:
        signum, _pending = _pending, None
        raise JobInterrupted(signum)


def acquire_stoppably(lock: Any, slice_s: float) -> None:
    """Acquire a `filelock` lock, waiting in slices of `slice_s` so that a stop signal that arrives
    while another process holds it still stops the job.

    A signal that arrived during the wait is raised even when the lock came free: the holder is
    often stopped by the same signal (a sweep's process group), and a waiter that went on would
    start the work the holder just gave up (reopen its training run, and leave it RUNNING)."""
    while True:
        try:
            lock.acquire(timeout=slice_s)
        except Timeout:
            raise_if_pending()
            continue
        if pending():
            lock.release()
            raise_if_pending()
        return


@contextmanager
def deferred() -> Iterator[None]:
    """A stop signal arriving inside waits for the next safe point after the block (none raises within)."""
    global _depth
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1


@contextmanager
def protected() -> Iterator[None]:
    """Let the write inside finish before a pending stop signal is raised."""
    with deferred():
        yield
    raise_if_pending()


@contextmanager
def signals_raise() -> Iterator[None]:
    """Within this block the stop signals raise `JobInterrupted` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    global _pending
    _previous.clear()
    for signum in STOP_SIGNALS:
        _previous[signum] = signal.signal(signum, _on_signal)
    try:
        yield
    finally:
        for signum, handler in _previous.items():
            signal.signal(signum, handler)
        _pending = None  # a signal after the last safe point came when the work was already done


def hand_on(interrupted: JobInterrupted) -> NoReturn:
    """After the job stopped cleanly: run the handler the job displaced (submitit's requeue), then exit."""
    handler: Callable[[int, FrameType | None], Any] | Any = _previous.get(interrupted.signum)
    if callable(handler) and handler is not signal.default_int_handler:
        handler(interrupted.signum, None)  # submitit: dumps the requeued call, requeues, sys.exit
    raise SystemExit(128 + interrupted.signum)
