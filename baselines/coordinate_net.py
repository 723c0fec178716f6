"""The Coordinate method: the camera stream plus an MLP over the raw V2X vector (no HGM).

The V2X vector is the K nearest connected vehicles, each (present, rel. lon, rel. lat, speed,
c_x, c_y), for every stacked frame: the same information the HGM rasterises, fed as numbers.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from hgm_repro.models.networks import PAPER_CONV, PAPER_HIDDEN, DuelingHead, ImageEncoder, decode_camera, mlp


class CoordinateDuelingQNet(nn.Module):
    """[conv(camera), MLP(coordinates)] concatenated -> dueling head."""

    in_keys = ["camera", "coordinates"]

    def __init__(self, n_actions: int, in_channels: int, image_size: Sequence[int],
                 coord_dim: int | None = None, conv: Sequence[Sequence[int]] = PAPER_CONV,
                 hidden: Sequence[int] = PAPER_HIDDEN, coord_hidden: Sequence[int] = (256, 256),
                 **unused: object):
        super().__init__()
        del unused
        if not coord_dim:
            raise ValueError("CoordinateDuelingQNet needs coord_dim (frame_stack * coord_k * 6)")
        self.conv = ImageEncoder(in_channels, image_size, conv)
        self.coord_mlp = mlp(int(coord_dim), coord_hidden)
        self.head = DuelingHead(self.conv.out_features + int(coord_hidden[-1]), n_actions, hidden)

    def forward(self, camera: torch.Tensor, coordinates: torch.Tensor) -> torch.Tensor:
        features = torch.cat([self.conv(decode_camera(camera)), self.coord_mlp(coordinates.float())], dim=-1)
        return self.head(features)
