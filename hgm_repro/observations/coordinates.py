"""The Coordinate method's observation: the raw V2X data of the K nearest connected vehicles.

The paper's Coordinate baseline feeds V2X data to the network directly, without the HGM. Here it
is a fixed-size vector per env: for each of the K connected, active vehicles in range nearest to
the host along the road (|dlon|, nearest first, the host itself excluded), six numbers

    present (1), rel. lon / D_r, rel. lat / road width, normalised speed (as in the HGM), c_x, c_y

(c_x: half length along the road, c_y: half width, in m), and rows of zeros after the last one.
"""

from __future__ import annotations

import torch

from ..simulator import HOST, HighwaySimulator, TrafficState
from .hyper_grid_matrix import normalised_speed, v2x_senders

FEATURES = 6


def coordinates(sim: HighwaySimulator, state: TrafficState | None = None, *, k: int = 16,
                v2x_range: float = 40.0) -> torch.Tensor:
    """float32 [N, K*6] (see the module docstring)."""
    s = sim.state if state is None else state
    n, m = s.pos_lon.shape
    rel_lon = s.pos_lon - s.pos_lon[:, HOST:HOST + 1]
    rel_lat = s.pos_lat - s.pos_lat[:, HOST:HOST + 1]
    senders = v2x_senders(sim, s, v2x_range)
    senders[:, HOST] = False
    kk = min(k, m)
    score = torch.where(senders, -rel_lon.abs(), torch.full_like(rel_lon, -float("inf")))
    top, idx = torch.topk(score, kk, dim=1, largest=True, sorted=True)
    present = torch.isfinite(top)
    road_width = sim.config.lanes * sim.config.lane_width
    feats = torch.stack([
        torch.ones_like(top),
        rel_lon.gather(1, idx) / v2x_range,
        rel_lat.gather(1, idx) / road_width,
        normalised_speed(s.speed.gather(1, idx), sim.config.v_min, sim.config.v_max),
        sim.half_len_by_type[s.vtype.gather(1, idx)],
        sim.half_wid_by_type[s.vtype.gather(1, idx)],
    ], dim=-1) * present.unsqueeze(-1)
    if kk < k:
        feats = torch.cat([feats, feats.new_zeros(n, k - kk, FEATURES)], dim=1)
    return feats.reshape(n, k * FEATURES).float()
