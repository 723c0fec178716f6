"""The road as the cameras paint it: its colours, lane markings and dashes, and pixels as packed
RGB int32 (a paint step then touches one number per pixel instead of three). Shared by the
front and the bird's-eye camera, so that both show the same road.
"""

from __future__ import annotations

import sys

import torch

ROAD = (105, 105, 110)
VERGE = (70, 125, 60)
MARKING = (235, 235, 235)
DASH_PERIOD = 12.0  # m: a 4 m dash, then an 8 m gap
DASH_LENGTH = 4.0
MARKING_HALF_WIDTH = 0.08  # m


def pack_rgb(rgb: torch.Tensor) -> torch.Tensor:
    """[..., 3] colours (0..255) -> [...] int32 r | g << 8 | b << 16."""
    c = rgb.round().clamp(0, 255).to(torch.int32)
    return c[..., 0] | (c[..., 1] << 8) | (c[..., 2] << 16)


def unpack_rgb(packed: torch.Tensor) -> torch.Tensor:
    """[N, H, W] packed int32 -> [N, 3, H, W] uint8."""
    n, h, w = packed.shape
    if sys.byteorder == "little":
        return packed.contiguous().view(torch.uint8).view(n, h, w, 4)[..., :3].permute(0, 3, 1, 2).contiguous()
    return torch.stack([(packed >> s) & 255 for s in (0, 8, 16)], dim=1).to(torch.uint8)  # pragma: no cover


def packed_colour(rgb: tuple[int, int, int]) -> float:
    """One colour as the packed number `pack_rgb` gives (a float, to paint with torch.where)."""
    return float(rgb[0] | (rgb[1] << 8) | (rgb[2] << 16))


def lane_markings(lat: torch.Tensor, lat_pixel: torch.Tensor, lanes: int, lane_width: float
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """On-road, solid-line and dashed-line masks at lateral positions `lat` (m from the left road
    edge); a marking is drawn at least one pixel (`lat_pixel` m) wide so that it never vanishes."""
    road_width = lanes * lane_width
    on_road = (lat >= 0) & (lat <= road_width)
    k = torch.round(lat / lane_width).clamp(0, lanes)
    near_line = (lat - k * lane_width).abs() <= torch.clamp(lat_pixel * 0.5, min=MARKING_HALF_WIDTH) + 1e-4
    edge = (k == 0) | (k == lanes)
    return on_road, near_line & edge, near_line & ~edge


def mix_colours(a: tuple[int, int, int], b: tuple[int, int, int], t: float) -> tuple[int, int, int]:
    """`a` blended towards `b` by the fraction `t`."""
    return tuple(int(round(x * (1 - t) + y * t)) for x, y in zip(a, b, strict=True))
