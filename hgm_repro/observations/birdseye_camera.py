"""The host's bird's-eye camera: a top-down RGB view of its surroundings, uint8 [N, 3, H, W].

It covers exactly the HGM's area, so the two images align cell for cell, and draws every active
vehicle (connected or not) in its own colour on the road and its lane markings.
"""

from __future__ import annotations

from functools import lru_cache

import torch

from ..simulator import HOST, HighwaySimulator, TrafficState
from .grid import GridGeometry, blend, paint_ranks
from .hyper_grid_matrix import hgm_geometry, host_first_priority
from .road_paint import (
    DASH_LENGTH,
    DASH_PERIOD,
    MARKING,
    ROAD,
    VERGE,
    lane_markings,
    pack_rgb,
    packed_colour,
    unpack_rgb,
)


def birdseye_geometry(sim: HighwaySimulator, height: int, width: int, v2x_range: float) -> GridGeometry:
    """The bird's-eye view covers exactly the HGM's area, so the two images align cell for cell."""
    return hgm_geometry(sim, height, width, v2x_range)


@lru_cache(maxsize=8)
def _birdseye_tables(lanes: int, lane_width: float, height: int, width: int, v2x_range: float,
                     device: str) -> tuple[torch.Tensor, torch.Tensor]:
    """Background with solid markings [H, W] packed int32, and the dashed-line columns [W]."""
    road_width = lanes * lane_width
    geom = GridGeometry(height, width, v2x_range, v2x_range, 0.0, road_width)
    lat = geom.col_centres(device)
    on_road, solid, dashed = lane_markings(lat, torch.full_like(lat, geom.dx), lanes, lane_width)
    row = torch.where(on_road, packed_colour(ROAD), packed_colour(VERGE))
    row = torch.where(solid | dashed, packed_colour(MARKING), row)
    return row.to(torch.int32).view(1, width).expand(height, width).contiguous(), dashed


def birdseye_camera(sim: HighwaySimulator, state: TrafficState | None = None, *, height: int = 84,
                    width: int = 84, v2x_range: float = 40.0) -> torch.Tensor:
    """A top-down RGB view of the host's surroundings (every active vehicle, connected or not, in
    its own colour; road and lane markings), uint8 [N, 3, H, W]; row 0 farthest ahead."""
    s = sim.state if state is None else state
    n = s.pos_lon.shape[0]
    d = s.pos_lon.device
    c = sim.config
    geom = birdseye_geometry(sim, height, width, v2x_range)
    bg, dashed = _birdseye_tables(c.lanes, float(c.lane_width), height, width, float(v2x_range), str(d))
    lon = s.pos_lon[:, HOST:HOST + 1] + geom.row_centres(d).view(1, height)  # [N, H]
    gap_row = torch.remainder(lon, DASH_PERIOD) >= DASH_LENGTH
    image = blend(bg.expand(n, height, width), torch.tensor(int(packed_colour(ROAD)), dtype=torch.int32, device=d),
                  gap_row.unsqueeze(-1) & dashed.view(1, 1, width))

    rel_lon = s.pos_lon - s.pos_lon[:, HOST:HOST + 1]
    shown = s.active & ((rel_lon.abs() - sim.half_len_by_type[s.vtype]) < v2x_range)
    rank, order = paint_ranks(
        geom, rel_lon, s.pos_lat, sim.half_len_by_type[s.vtype], sim.half_wid_by_type[s.vtype], shown=shown,
        priority=host_first_priority(rel_lon), max_half_len=sim.max_half_len, max_half_wid=sim.max_half_wid)
    k = order.shape[1]
    colour = pack_rgb(s.color.gather(1, order.unsqueeze(-1).expand(n, k, 3)).float())
    colour_by_rank = torch.cat([colour, colour.new_zeros(n, 1)], dim=1)
    painted = colour_by_rank.gather(1, rank.long().view(n, -1)).view(n, height, width)
    image = blend(image, painted, rank < k)
    return unpack_rgb(image)
