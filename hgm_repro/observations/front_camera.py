"""The host's forward RGB camera: a pinhole camera at the front bumper, as uint8 [N, 3, H, W].

Geometry: a pinhole camera at the host's front bumper, `camera_height` above the
road, looking along the road (the host's heading during a lane change is ignored). Square pixels
with focal length f = (W/2) / tan(fov/2). A level camera puts the horizon on the image's middle
row and spends half the image on sky; `pitch_deg` aims the view down by that angle the way a
view camera's shifted lens does: the image plane stays vertical (vertical edges stay vertical and
the one-ray-per-column occlusion rule below stays exact) and the horizon moves up by
f tan(pitch) rows. A point z metres ahead, x metres to the right and y metres high lands on
column W/2 + f x / z, row H/2 - f tan(pitch) - f (y - camera_height) / z.

Ground: every pixel below the horizon sees the road plane at z = f * camera_height / (row - H/2);
from z and the column, its position on the road decides road / verge / lane marking.

Vehicles are boxes (collision box footprint, `vehicle_height` tall) in their own random colour,
which does not depend on the vehicle's type: the camera cannot tell connected vehicles apart.
Each image column casts one ray in the road plane (a slab test against every box footprint:
[N, M, W]) and keeps the nearest box it hits. Because every vehicle is taller than the camera,
a nearer box's rows contain a farther box's rows in the same column, so the nearest box per
column is all that is visible; its rows are painted with one [N, H, W] comparison. Only
vehicles whose whole body is ahead of the camera (and nearer than `max_range`) are drawn:
a vehicle beside or behind the host never appears. A far vehicle is drawn at least one pixel
wide and tall (a splat), so that it cannot fall between two pixel centres and vanish.

Speed: the road seen from the camera depends only on the host's lateral position (quantised to
LAT_STEP) and, for the dashes, on its position along the road modulo the dash period. So the
backgrounds are computed once per lateral position into a lookup table and each frame only
gathers them and blanks the dash gaps row by row. Pixels are handled as packed RGB int32 until
the very end, so that a paint step touches one number per pixel instead of three, and painting
uses arithmetic instead of torch.where (see grid.blend).
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch

from ..simulator import HOST, HighwaySimulator, TrafficState
from .grid import blend
from .road_paint import (
    DASH_LENGTH,
    DASH_PERIOD,
    MARKING,
    ROAD,
    VERGE,
    lane_markings,
    mix_colours,
    pack_rgb,
    packed_colour,
    unpack_rgb,
)

NEAR_PLANE = 0.1  # m
LAT_STEP = 0.05  # m: resolution of the host's lateral position in the background table

SKY_TOP = (110, 160, 230)
SKY_HORIZON = (190, 215, 240)
# Shades of a vehicle's colour: side faces, and the band below BUMPER_TOP (bumper, tyres, shadow).
SIDE_SHADE, BUMPER_SHADE = 0.75, 0.45
BUMPER_TOP = 0.4  # m above the road



@lru_cache(maxsize=8)
def _front_tables(lanes: int, lane_width: float, height: int, width: int, fov_deg: float, camera_height: float,
                  horizon_shift: float, device: str
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, int]:
    """Background per quantised lateral camera position, [L, H, W] packed int32, the mask of
    dashed-line pixels [L, H - first, W] from row `first` (the first row that resolves dashes) on,
    the ground distance of each row [H], whether a row resolves dashes [H], and `first`."""
    f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    road_width = lanes * lane_width
    cam_lat = torch.arange(0, int(round(road_width / LAT_STEP)) + 1, device=device) * LAT_STEP  # [L]
    # Row centres measured from the horizon (positive below it).
    row_c = torch.arange(height, device=device, dtype=torch.float32) + 0.5 - height / 2 + horizon_shift
    col_c = torch.arange(width, device=device, dtype=torch.float32) + 0.5 - width / 2
    below = row_c > 0
    z = torch.where(below, f * camera_height / row_c.clamp(min=1e-6), torch.zeros_like(row_c))
    # A row resolves dashes while its footprint along the road is under half a dash period.
    footprint = f * camera_height / (row_c - 0.5).clamp(min=1e-3) - z
    resolved = below & (footprint < DASH_PERIOD / 2)
    lat = cam_lat.view(-1, 1, 1) + (col_c / f).view(1, 1, width) * z.view(1, height, 1)
    lat_pixel = (z / f).view(1, height, 1).expand_as(lat)
    on_road, solid, dashed = lane_markings(lat, lat_pixel, lanes, lane_width)
    bg = torch.where(on_road, packed_colour(ROAD), packed_colour(VERGE))
    bg = torch.where(solid, packed_colour(MARKING), bg)
    # Dashes a row cannot resolve show as a faint continuous line of their average brightness.
    faint = packed_colour(mix_colours(ROAD, MARKING, DASH_LENGTH / DASH_PERIOD))
    bg = torch.where(dashed, torch.where(resolved.view(1, height, 1), packed_colour(MARKING), faint), bg)
    t = (row_c.clamp(max=0) / -max(height / 2 - horizon_shift, 1.0)).clamp(max=1)
    sky = torch.tensor([packed_colour(mix_colours(SKY_HORIZON, SKY_TOP, float(x))) for x in t], device=device)
    bg = torch.where(below.view(1, height, 1), bg, sky.view(1, height, 1))
    dashed = dashed & resolved.view(1, height, 1)
    # Only rows that resolve dashes can show a gap: keep the table from the first such row on.
    first = int(resolved.nonzero()[0]) if bool(resolved.any()) else height
    return bg.to(torch.int32), dashed[:, first:].contiguous(), z, resolved, first


def front_camera(sim: HighwaySimulator, state: TrafficState | None = None, *, height: int = 84, width: int = 84,
                 fov_deg: float = 90.0, camera_height: float = 1.2, pitch_deg: float = 0.0,
                 vehicle_height: float = 1.5, max_range: float = 150.0) -> torch.Tensor:
    """The host's forward RGB camera, uint8 [N, 3, H, W] (see the module docstring)."""
    s = sim.state if state is None else state
    n = s.pos_lon.shape[0]
    d = s.pos_lon.device
    c = sim.config
    f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    if vehicle_height <= camera_height:
        raise ValueError(f"vehicle_height={vehicle_height} must exceed camera_height={camera_height}: the per-column "
                         "occlusion rule needs every vehicle to reach above the camera")
    horizon_shift = f * math.tan(math.radians(pitch_deg))  # rows the horizon sits above the middle row
    half_len, half_wid = sim.half_len_by_type[s.vtype], sim.half_wid_by_type[s.vtype]
    cam_lon = s.pos_lon[:, HOST] + half_len[:, HOST]  # [N]
    cam_lat = s.pos_lat[:, HOST]

    # --- background: table lookup by lateral position, then the dash gaps of this position.
    bg, dashed, z, resolved, first = _front_tables(c.lanes, float(c.lane_width), height, width, float(fov_deg),
                                                   float(camera_height), float(horizon_shift), str(d))
    lat_index = torch.round(cam_lat / LAT_STEP).long().clamp(0, bg.shape[0] - 1)
    gap_row = resolved & (torch.remainder(cam_lon.unsqueeze(1) + z, DASH_PERIOD) >= DASH_LENGTH)  # [N, H]
    road = torch.tensor(int(packed_colour(ROAD)), dtype=torch.int32, device=d)
    image = bg.index_select(0, lat_index)  # [N, H, W] packed
    gap = dashed.index_select(0, lat_index) & gap_row[:, first:].unsqueeze(-1)
    image[:, first:] = blend(image[:, first:], road, gap)

    # --- vehicles: only those wholly ahead and in range, nearest first.
    z0 = s.pos_lon - half_len - cam_lon.unsqueeze(1)  # near face, [N, M]
    shown = s.active & (z0 > NEAR_PLANE) & (z0 < max_range)
    shown[:, HOST] = False
    k = int(shown.sum(1).max())
    if k == 0:
        return unpack_rgb(image)
    top_score, who_k = torch.topk(torch.where(shown, -z0, torch.full_like(z0, -float("inf"))), k, dim=1)
    keep = torch.isfinite(top_score)
    z0 = z0.gather(1, who_k)
    z1 = z0 + 2 * half_len.gather(1, who_k)
    x_c = s.pos_lat.gather(1, who_k) - cam_lat.unsqueeze(1)
    # At least one pixel wide, so that a far car between two column rays does not vanish.
    hw = torch.maximum(half_wid.gather(1, who_k), 0.51 * z1 / f)
    x0, x1 = x_c - hw, x_c + hw
    # --- per column, the nearest box footprint its ray enters (slab test; the ray is x = slope * z).
    col_c = torch.arange(width, device=d, dtype=torch.float32) + 0.5 - width / 2
    slope = col_c / f
    inv = (1 / torch.where(slope.abs() < 1e-9, torch.full_like(slope, 1e-9), slope)).view(1, 1, width)
    za, zb = x0.unsqueeze(-1) * inv, x1.unsqueeze(-1) * inv  # [N, K, W]
    side_in = torch.minimum(za, zb)
    enter = torch.maximum(z0.unsqueeze(-1), side_in)
    leave = torch.minimum(z1.unsqueeze(-1), torch.maximum(za, zb))
    hit = (enter < leave) & keep.unsqueeze(-1)
    depth = torch.where(hit, enter, torch.full_like(enter, float("inf")))
    nearest, who = depth.min(dim=1)  # [N, W]
    seen_side = side_in.gather(1, who.unsqueeze(1)).squeeze(1) > z0.gather(1, who)
    slot = who_k.gather(1, who)
    rgb = s.color.gather(1, slot.unsqueeze(-1).expand(n, width, 3)).float()
    rgb = rgb * torch.where(seen_side, SIDE_SHADE, 1.0).unsqueeze(-1)
    body, bumper = pack_rgb(rgb).unsqueeze(1), pack_rgb(rgb * BUMPER_SHADE).unsqueeze(1)  # [N, 1, W]

    # --- paint: rows between the box's top and bottom at that depth, the lowest band darker.
    # Columns that see no vehicle get empty row ranges (all bounds +inf).
    visible = torch.isfinite(nearest)
    scale = f / nearest  # pixels per metre at that depth; 0 where nothing is hit
    row_of = lambda height_m: torch.where(scale > 0, (camera_height - height_m) * scale, float("inf")).unsqueeze(1)
    top_row = row_of(vehicle_height)
    bumper_row = row_of(BUMPER_TOP)
    bottom_row = torch.maximum(row_of(0.0), top_row + 1)  # at least one pixel tall, as above
    # Vehicles cover only a band of rows around the horizon unless one is very near: paint that
    # band only (one small read-back for its bounds).
    seen = visible.unsqueeze(1)
    lo, hi = torch.stack([torch.where(seen, top_row, 1e9).min(), torch.where(seen, bottom_row, -1e9).max()]).tolist()
    r0 = max(0, min(height, math.floor(lo + height / 2 - horizon_shift)))
    r1 = max(r0, min(height, math.ceil(hi + height / 2 - horizon_shift)))
    rows = (torch.arange(r0, r1, device=d, dtype=torch.float32) + 0.5 - height / 2 + horizon_shift).view(1, -1, 1)
    band = image[:, r0:r1]
    band = blend(band, body, (rows >= top_row) & (rows < bumper_row))
    image[:, r0:r1] = blend(band, bumper, (rows >= bumper_row) & (rows < bottom_row))
    return unpack_rgb(image)
