"""Min's method: the proposed network without the HGM stream (front camera only, no V2X)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from hgm_repro.models.networks import PAPER_CONV, PAPER_HIDDEN, DuelingHead, ImageEncoder, decode_camera


class MinDuelingQNet(nn.Module):
    """Camera stack -> the paper's conv stack -> dueling head."""

    in_keys = ["camera"]

    def __init__(self, n_actions: int, in_channels: int, image_size: Sequence[int],
                 coord_dim: int | None = None, conv: Sequence[Sequence[int]] = PAPER_CONV,
                 hidden: Sequence[int] = PAPER_HIDDEN, **unused: object):
        super().__init__()
        del coord_dim, unused  # same constructor as the other networks
        self.conv = ImageEncoder(in_channels, image_size, conv)
        self.head = DuelingHead(self.conv.out_features, n_actions, hidden)

    def forward(self, camera: torch.Tensor) -> torch.Tensor:
        return self.head(self.conv(decode_camera(camera)))
