"""Who is ahead of and behind whom, per lane, for every vehicle of every env at once.

A vehicle occupies each lane its body overlaps and, while changing lanes, the lane it is
changing into (so that others see the reservation from the moment the change starts).
Sorting by longitudinal position and a reverse cumulative minimum over ranks gives, for each
vehicle and each lane, the nearest occupant ahead and behind: O(envs x vehicles x lanes),
with no pairwise [envs, vehicles, vehicles] tensor.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

NONE = -1  # index used where no vehicle exists


def lane_occupancy(pos_lat: torch.Tensor, half_width: torch.Tensor, target_lane: torch.Tensor,
                   active: torch.Tensor, lanes: int, lane_width: float) -> torch.Tensor:
    """Boolean [N, M, lanes]: which lanes each vehicle's body or lane-change reservation covers."""
    edges = torch.arange(lanes + 1, device=pos_lat.device, dtype=pos_lat.dtype) * lane_width
    lo = (pos_lat - half_width).unsqueeze(-1)
    hi = (pos_lat + half_width).unsqueeze(-1)
    occ = (lo < edges[1:]) & (hi > edges[:-1])
    occ = occ | F.one_hot(target_lane.clamp(0, lanes - 1), lanes).bool()
    return occ & active.unsqueeze(-1)


@dataclass
class Neighbours:
    """lead[n, i, l] / follow[n, i, l]: index of the nearest vehicle ahead / behind vehicle i that
    occupies lane l in env n, or NONE. `occupancy` is the table they were computed from."""

    lead: torch.Tensor
    follow: torch.Tensor
    occupancy: torch.Tensor


def nearest_per_lane(pos_lon: torch.Tensor, occupancy: torch.Tensor, with_follow: bool = True) -> Neighbours:
    """Lead (and, unless `with_follow` is False, follow) tables for every vehicle and lane."""
    n, m, lanes = occupancy.shape
    device = pos_lon.device
    order = pos_lon.argsort(dim=1, stable=True)  # rank -> vehicle
    ranks = torch.arange(m, device=device)
    rank_of = torch.empty_like(order).scatter_(1, order, ranks.expand(n, m))  # vehicle -> rank
    occ_sorted = occupancy.gather(1, order.unsqueeze(-1).expand(n, m, lanes))
    # Ranks as int16 and arithmetic instead of torch.where: several times faster on CPU, and
    # ranks never exceed a few hundred. A non-occupant gets a rank outside [0, m).
    r = ranks.to(torch.int16).view(1, m, 1)
    vacant = (~occ_sorted).to(torch.int16)
    # Nearest occupant at a strictly higher rank (ahead) / strictly lower rank (behind).
    at_or_after = (r + vacant * m).flip(1).cummin(1).values.flip(1)
    ahead = torch.cat([at_or_after[:, 1:], at_or_after.new_full((n, 1, lanes), m)], dim=1)

    def to_vehicle(rank_table: torch.Tensor) -> torch.Tensor:
        # rank of neighbour -> neighbour's vehicle index (NONE if no neighbour); then rows re-indexed
        # by the asking vehicle.
        missing = ((rank_table < 0) | (rank_table >= m)).long()
        idx = order.gather(1, rank_table.long().clamp(0, m - 1).reshape(n, m * lanes)).reshape(n, m, lanes)
        idx = idx - (idx - NONE) * missing
        return idx.gather(1, rank_of.unsqueeze(-1).expand(n, m, lanes))

    lead = to_vehicle(ahead)
    follow = lead
    if with_follow:
        at_or_before = (r - vacant * (m + 1)).cummax(1).values
        behind = torch.cat([at_or_before.new_full((n, 1, lanes), -1), at_or_before[:, :-1]], dim=1)
        follow = to_vehicle(behind)
    return Neighbours(lead=lead, follow=follow, occupancy=occupancy)


def gather_vehicles(values: torch.Tensor, index: torch.Tensor, fill: float) -> torch.Tensor:
    """values [N, M] gathered at index [N, ...] (NONE gives `fill`)."""
    n = values.shape[0]
    flat = index.reshape(n, -1)
    out = values.gather(1, flat.clamp(min=0))
    out = torch.where(flat < 0, fill, out)
    return out.reshape(index.shape)
