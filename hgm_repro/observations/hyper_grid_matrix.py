"""The Hyper-Grid Matrix (Algorithm 1): V2X data of connected vehicles mapped onto a grid.

Layout: rows run along the road over [-D_r, +D_r] around the host, row 0 farthest ahead (so
"up" is forward, as in the camera image); columns run across the full road width, column 0 at
the left road edge. The grid has the camera image's height and width so that both streams can
go through one shared conv stack.

Who appears: only vehicles that send V2X data (connected types: NCV and the host) and are
active, with |lon_i - lon_host| < D_r (strict, as in Algorithm 1). CHV and AHV never appear.

Cell value: (v - (v_max + v_min)/2) / ((v_max + v_min)/2) on cells covered by the vehicle's
collision box (half extents c_x along the road, c_y across it), 0 elsewhere. Coverage rule and
overlap rule: see `grid.py` (cell centre strictly inside the box; the host, then the vehicle
nearest to the host along the road, wins a cell where boxes overlap).

Two options that depart from the paper (off by default):
- `ahead`: the window (and V2X reception) reaches this far ahead instead of D_r; it still reaches
  D_r behind. Shedding 26 km/h at the host's braking rate takes about 57 m, more than D_r = 40 m.
- `host_cell="own_range"`: the host's cell maps its speed linearly onto [-1, just below the lowest
  value any other vehicle can write], so that it differs from an empty cell (0) at every speed; under
  the paper's formula the host is invisible at the mid speed (60 km/h), where every host starts.

Variants (always 3 channels, like the RGB image):
- "paper": the value repeated on the 3 channels;
- "enriched": (value, occupancy, host cell), occupancy and host cell written as -1 (no) / +1
  (yes), so that every channel lies in [-1, 1] and the one uint8 encoding serves all
  (uint8 0 / 255). The occupancy channel removes the formula's blind spot: a vehicle at exactly
  the mid speed writes 0, like an empty cell.
"""

from __future__ import annotations

import torch

from ..simulator import HOST, HighwaySimulator, TrafficState
from .grid import GridGeometry, paint_ranks


def hgm_geometry(sim: HighwaySimulator, height: int, width: int, v2x_range: float,
                 ahead: float = 0.0) -> GridGeometry:
    """The HGM's grid: D_r behind the host, `ahead` m ahead of it (0: D_r), across the whole road."""
    road_width = sim.config.lanes * sim.config.lane_width
    return GridGeometry(height=height, width=width, ahead=ahead or v2x_range, behind=v2x_range, left=0.0,
                        right=road_width)


def normalised_speed(speed: torch.Tensor, v_min: float, v_max: float) -> torch.Tensor:
    """Algorithm 1's cell value: the speed relative to the middle of the allowed range."""
    mid = (v_max + v_min) / 2
    return (speed - mid) / mid


def v2x_senders(sim: HighwaySimulator, state: TrafficState, v2x_range: float, ahead: float = 0.0) -> torch.Tensor:
    """[N, M] bool: vehicles whose V2X data the host receives (the host itself included): within D_r
    behind and D_r (or `ahead` m, when > 0) ahead."""
    rel_lon = state.pos_lon - state.pos_lon[:, HOST:HOST + 1]
    in_range = (rel_lon > -v2x_range) & (rel_lon < (ahead or v2x_range))
    return sim.connected_by_type[state.vtype] & state.active & in_range


def host_cell_values(value: torch.Tensor, speed: torch.Tensor, v_min: float, v_max: float,
                     host_cell: str) -> torch.Tensor:
    """[N, M] cell values with the host's (slot HOST) replaced under `host_cell="own_range"`: its speed
    mapped linearly onto [-1, lowest - 2/255], where `lowest` is the value of a vehicle at v_min, so
    that the host never writes another vehicle's value nor the empty cell's 0 (uint8 steps are 1/127.5)."""
    if host_cell == "paper":
        return value
    lowest = float(normalised_speed(torch.tensor(v_min), v_min, v_max))
    share = ((speed[:, HOST] - v_min) / (v_max - v_min)).clamp(0.0, 1.0)
    value = value.clone()
    value[:, HOST] = -1.0 + share * (lowest - 2.0 / 127.5 + 1.0)
    return value


def host_first_priority(rel_lon: torch.Tensor) -> torch.Tensor:
    """Overlap priority: the host, then vehicles nearer to it along the road."""
    priority = rel_lon.abs().clone()
    priority[:, HOST] = -1.0
    return priority


def hyper_grid_matrix(sim: HighwaySimulator, state: TrafficState | None = None, *, height: int = 84,
                      width: int = 84, v2x_range: float = 40.0, variant: str = "paper",
                      encoded: bool = False, ahead: float = 0.0, host_cell: str = "paper") -> torch.Tensor:
    """The HGM, [N, 3, H, W] (see the module docstring): float32 values in [-1, 1], or with
    `encoded` the uint8 `encode_hgm` of them, computed without a float image in between."""
    if variant not in ("paper", "enriched"):
        raise ValueError(f"hgm variant={variant!r} is not allowed; allowed: ['paper', 'enriched']")
    s = sim.state if state is None else state
    n = s.pos_lon.shape[0]
    geom = hgm_geometry(sim, height, width, v2x_range, ahead)
    rel_lon = s.pos_lon - s.pos_lon[:, HOST:HOST + 1]
    v_min, v_max = sim.config.v_min, sim.config.v_max
    value = host_cell_values(normalised_speed(s.speed, v_min, v_max).clamp(-1.0, 1.0), s.speed, v_min, v_max,
                             host_cell)
    key, order = paint_ranks(
        geom, rel_lon, s.pos_lat, sim.half_len_by_type[s.vtype], sim.half_wid_by_type[s.vtype],
        shown=v2x_senders(sim, s, v2x_range, ahead), priority=host_first_priority(rel_lon),
        max_half_len=sim.max_half_len, max_half_wid=sim.max_half_wid,
        payload=encode_hgm(value))
    k = order.shape[1]
    if encoded:
        grid = key.to(torch.uint8)  # the low byte: the winner's encoded value (casting wraps mod 256)
        yes, no = 255, 0
    else:
        # Exact values (not quantised to uint8): look the winner's value up by its rank.
        value_by_rank = torch.cat([value.gather(1, order), value.new_zeros(n, 1)], dim=1)
        grid = value_by_rank.gather(1, (key >> 8).long().view(n, -1)).view(n, height, width)
        yes, no = 1.0, -1.0
    grid = grid.unsqueeze(1)
    if variant == "paper":
        return grid.expand(n, 3, height, width)
    # yes/no flags by arithmetic: torch.where is much slower on CPU here (see grid.blend).
    flag = lambda mask: (mask.to(grid.dtype) * (yes - no) + no).unsqueeze(1)
    # key = rank * 256 + value; the host has the smallest priority and is always shown: rank 0.
    return torch.cat([grid, flag(key < k * 256), flag(key < 256)], dim=1)


def encode_hgm(values: torch.Tensor) -> torch.Tensor:
    """HGM values in [-1, 1] -> uint8, round((v + 1) * 127.5): the dtype the replay buffer stores."""
    return torch.round((values.clamp(-1.0, 1.0) + 1.0) * 127.5).to(torch.uint8)


def decode_hgm(encoded: torch.Tensor) -> torch.Tensor:
    """uint8 -> HGM values in [-1, 1] (within 1/255 of the original)."""
    return encoded.float() / 127.5 - 1.0
