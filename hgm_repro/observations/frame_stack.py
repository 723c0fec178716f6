"""Stacks of the last F frames per env, as the paper's network reads several frames at once."""

from __future__ import annotations

import torch


class FrameStack:
    """Keeps [N, F*C, ...] stacks, oldest frame first, newest last (channels of one frame stay together).

    `reset(frame, mask)` refills the masked envs' stacks entirely with `frame`, so no frame of a
    previous episode survives into a new one; `push(frame)` drops the oldest frame of every env.
    """

    def __init__(self, n_frames: int):
        if not isinstance(n_frames, int) or n_frames < 1:
            raise ValueError(f"frame_stack={n_frames!r} is not allowed: need a whole number >= 1")
        self.n_frames = n_frames
        self.stack: torch.Tensor | None = None
        self._c = 0

    def reset(self, frame: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """`frame` [N, C, ...]; envs where `mask` is True (all when None, or before any frame) restart."""
        if self.stack is None or mask is None or self.stack.shape[0] != frame.shape[0] \
                or self.stack.dtype != frame.dtype or self.stack.device != frame.device:
            self._c = frame.shape[1]
            self.stack = frame.repeat(1, self.n_frames, *([1] * (frame.dim() - 2)))
            return self.stack
        rows = mask.to(frame.device).reshape(-1).nonzero().squeeze(1)
        return self.refill(rows, frame.index_select(0, rows))

    def refill(self, rows: torch.Tensor, frames: torch.Tensor) -> torch.Tensor:
        """Restart the envs in `rows` (LongTensor [R]) from their first frames `frames` [R, C, ...]."""
        if self.stack is None:
            raise ValueError("refill needs a stack: reset with frames of every env first")
        # A new tensor: the caller may still hold the previous stack (the last step's observation).
        self.stack = self.stack.clone()
        self.stack[rows] = frames.repeat(1, self.n_frames, *([1] * (frames.dim() - 2)))
        return self.stack

    def push(self, frame: torch.Tensor) -> torch.Tensor:
        """Append the newest frame [N, C, ...] to every env's stack and drop the oldest."""
        if self.stack is None:
            return self.reset(frame)
        c = frame.shape[1]
        if c != self._c:
            raise ValueError(f"frame has {c} channels, the stack holds frames of {self._c}")
        self.stack = torch.cat([self.stack[:, c:], frame], dim=1)
        return self.stack
