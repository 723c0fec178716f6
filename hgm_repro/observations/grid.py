"""Painting axis-aligned vehicle boxes onto a top-down grid, batched, without a per-vehicle loop.

Shared by the Hyper-Grid Matrix and the bird's-eye camera, so both draw a vehicle on exactly
the same cells.

Coverage rule: a cell is covered by a box when the cell's centre lies strictly inside the box
(the strict inequalities of Algorithm 1, applied to cell centres). A box therefore covers
about 2*c_x/dy rows and 2*c_y/dx columns, and a box smaller than a cell may cover none.

Overlaps: where boxes overlap (only during a collision) the vehicle with the smallest
priority value wins the cell; callers give the host the smallest, then nearest along the road.

How: each vehicle can cover at most a small, fixed number of rows and columns (its collision
box is bounded), so every vehicle gets a fixed patch of candidate cells [N, M, Pr, Pc] around
its first covered row and column; candidates are tested against the rule and scattered with an
`amin` reduction of the vehicle's rank. Nothing of size [N, M, H, W] is ever built.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class GridGeometry:
    """A top-down grid: rows along the road (row 0 farthest ahead), columns across it (col 0 left)."""

    height: int
    width: int
    ahead: float  # m covered ahead of the host (to the top edge of row 0)
    behind: float  # m covered behind the host (to the bottom edge of the last row)
    left: float  # lateral position of the left edge of column 0 (m from the left road edge)
    right: float  # lateral position of the right edge of the last column

    @property
    def dy(self) -> float:
        return (self.ahead + self.behind) / self.height

    @property
    def dx(self) -> float:
        return (self.right - self.left) / self.width

    def row_centres(self, device: torch.device | str) -> torch.Tensor:
        """Longitudinal position of each row's centre relative to the host, [H]."""
        return self.ahead - (torch.arange(self.height, device=device, dtype=torch.float32) + 0.5) * self.dy

    def col_centres(self, device: torch.device | str) -> torch.Tensor:
        """Lateral position of each column's centre (from the left road edge), [W]."""
        return self.left + (torch.arange(self.width, device=device, dtype=torch.float32) + 0.5) * self.dx

    def patch_size(self, max_half_len: float, max_half_wid: float) -> tuple[int, int]:
        # Open interval of length 2c holds at most ceil(2c/d) centres; one more for rounding
        # of the starting index.
        return (min(self.height, math.ceil(2 * max_half_len / self.dy) + 2),
                min(self.width, math.ceil(2 * max_half_wid / self.dx) + 2))


def blend(image: torch.Tensor, colour: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """`colour` where `mask`, else `image` (broadcasting), for integer images.

    Same result as torch.where, but written as image + (colour - image) * mask: on CPU this
    torch's `where` over a broadcast image is over ten times slower than the arithmetic, and for
    uint8 the wrap-around of the difference cancels exactly.
    """
    return image + (colour.to(image.dtype) - image) * mask.to(image.dtype)


def paint_ranks(geom: GridGeometry, rel_lon: torch.Tensor, lat: torch.Tensor, half_len: torch.Tensor,
                half_wid: torch.Tensor, shown: torch.Tensor, priority: torch.Tensor,
                max_half_len: float, max_half_wid: float,
                payload: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Which vehicle covers each cell.

    Args: per vehicle [N, M]: `rel_lon` (m ahead of the host), `lat` (m from the left road
    edge), collision-box half extents, `shown` (drawn at all), `priority` (smaller wins overlaps).
    Returns `(rank, order)`: `order` [N, K] holds the slots of the shown vehicles sorted by
    priority (K = the most shown vehicles in any env; where an env shows fewer, its last entries
    are arbitrary slots that cover nothing); `rank` [N, H, W] long is the covering vehicle's
    position in `order`, or K where no vehicle covers the cell.

    With `payload` ([N, M] integers in 0..255, e.g. an encoded HGM value, and 128 meaning
    "empty"), `rank` instead holds rank * 256 + the winning vehicle's payload (K * 256 + 128
    where empty): one int32 scatter then gives both who won and what it writes, without a
    gather over the whole image afterwards.
    """
    n, m = rel_lon.shape
    h, w = geom.height, geom.width
    device = rel_lon.device
    pr, pc = geom.patch_size(max_half_len, max_half_wid)

    # Keep only the shown vehicles, sorted by priority: a few out of M, which is where the time
    # goes. K is read back to the host (one sync on CUDA) so that the work shrinks with it.
    k = max(1, int(shown.sum(1).max()))
    score = torch.where(shown, -priority, torch.full_like(priority, -float("inf")))
    # A stable sort, not topk: vehicles of equal priority (the same distance from the host) then
    # rank in slot order, the lower slot winning the cells they share, on every device.
    top, order = torch.sort(score, dim=1, descending=True, stable=True)
    top, order = top[:, :k], order[:, :k]
    keep = torch.isfinite(top)
    rel_lon, lat = rel_lon.gather(1, order), lat.gather(1, order)
    half_len, half_wid = half_len.gather(1, order), half_wid.gather(1, order)

    # First candidate row/column: the one just before the first centre inside the box.
    first_row = torch.floor((geom.ahead - rel_lon - half_len) / geom.dy - 0.5).long()
    first_col = torch.floor((lat - half_wid - geom.left) / geom.dx - 0.5).long()
    rows = first_row.unsqueeze(-1) + torch.arange(pr, device=device)  # [N, K, Pr]
    cols = first_col.unsqueeze(-1) + torch.arange(pc, device=device)  # [N, K, Pc]
    # Apply the coverage rule on the same centre formula as GridGeometry, so tests agree exactly.
    row_c = geom.ahead - (rows.float() + 0.5) * geom.dy
    col_c = geom.left + (cols.float() + 0.5) * geom.dx
    row_ok = ((row_c - rel_lon.unsqueeze(-1)).abs() < half_len.unsqueeze(-1)) & (rows >= 0) & (rows < h)
    col_ok = ((col_c - lat.unsqueeze(-1)).abs() < half_wid.unsqueeze(-1)) & (cols >= 0) & (cols < w)
    row_ok = row_ok & keep.unsqueeze(-1)

    ok = row_ok.unsqueeze(-1) & col_ok.unsqueeze(-2)  # [N, K, Pr, Pc]
    cell = rows.clamp(0, h - 1).unsqueeze(-1) * w + cols.clamp(0, w - 1).unsqueeze(-2)
    dump = h * w  # candidates that fail the rule land in one spare cell
    index = blend(cell, torch.tensor(dump, device=device), ~ok).reshape(n, -1)
    key = torch.arange(k, device=device, dtype=torch.int32).view(1, k).expand(n, k)
    empty = k
    if payload is not None:
        key = key * 256 + payload.gather(1, order).to(torch.int32)
        empty = k * 256 + 128
    key = key.view(n, k, 1, 1).expand(n, k, pr, pc).reshape(n, -1)
    rank = torch.full((n, h * w + 1), empty, dtype=torch.int32, device=device)
    rank.scatter_reduce_(1, index, key, reduce="amin", include_self=True)
    return rank[:, :dump].view(n, h, w), order
