"""The host's RGB camera: a forward pinhole camera, or a bird's-eye view, as uint8 [N, 3, H, W].

Front camera geometry: a level pinhole camera at the host's front bumper, `camera_height` above
the road, looking along the road (the host's heading during a lane change is ignored). Square
pixels with focal length f = (W/2) / tan(fov/2), so the horizon is the image's middle row and a
point z metres ahead, x metres to the right and y metres high lands on column W/2 + f x / z,
row H/2 - f (y - camera_height) / z.

Ground: every pixel below the horizon sees the road plane at z = f * camera_height / (row - H/2);
from z and the column, its position on the road decides road / verge / lane marking.

Vehicles are boxes (collision box footprint, VEHICLE_HEIGHT tall) in their own random colour,
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
import sys
from functools import lru_cache

import torch

from ..simulator import HOST, HighwaySimulator, TrafficState
from .grid import GridGeometry, blend, paint_ranks
from .hyper_grid_matrix import hgm_geometry, host_first_priority

VEHICLE_HEIGHT = 1.5  # m; must exceed the camera height for the per-column occlusion rule
NEAR_PLANE = 0.1  # m
LAT_STEP = 0.05  # m: resolution of the host's lateral position in the background table

SKY_TOP = (110, 160, 230)
SKY_HORIZON = (190, 215, 240)
ROAD = (105, 105, 110)
VERGE = (70, 125, 60)
MARKING = (235, 235, 235)
DASH_PERIOD = 12.0  # m: a 4 m dash, then an 8 m gap
DASH_LENGTH = 4.0
MARKING_HALF_WIDTH = 0.08  # m
# Shades of a vehicle's colour: side faces, and the band below BUMPER_TOP (bumper, tyres, shadow).
SIDE_SHADE, BUMPER_SHADE = 0.75, 0.45
BUMPER_TOP = 0.4  # m above the road


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


def _colour(rgb: tuple[int, int, int]) -> float:
    return float(rgb[0] | (rgb[1] << 8) | (rgb[2] << 16))


def _markings(lat: torch.Tensor, lat_pixel: torch.Tensor, lanes: int, lane_width: float
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """On-road, solid-line and dashed-line masks at lateral positions `lat` (m from the left road
    edge); a marking is drawn at least one pixel (`lat_pixel` m) wide so that it never vanishes."""
    road_width = lanes * lane_width
    on_road = (lat >= 0) & (lat <= road_width)
    k = torch.round(lat / lane_width).clamp(0, lanes)
    near_line = (lat - k * lane_width).abs() <= torch.clamp(lat_pixel * 0.5, min=MARKING_HALF_WIDTH) + 1e-4
    edge = (k == 0) | (k == lanes)
    return on_road, near_line & edge, near_line & ~edge


def _blend(a: tuple[int, int, int], b: tuple[int, int, int], t: float) -> tuple[int, int, int]:
    return tuple(int(round(x * (1 - t) + y * t)) for x, y in zip(a, b, strict=True))


@lru_cache(maxsize=8)
def _front_tables(lanes: int, lane_width: float, height: int, width: int, fov_deg: float, camera_height: float,
                  device: str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, int]:
    """Background per quantised lateral camera position, [L, H, W] packed int32, the mask of
    dashed-line pixels [L, H - first, W] from row `first` (the first row that resolves dashes) on,
    the ground distance of each row [H], whether a row resolves dashes [H], and `first`."""
    f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    road_width = lanes * lane_width
    cam_lat = torch.arange(0, int(round(road_width / LAT_STEP)) + 1, device=device) * LAT_STEP  # [L]
    row_c = torch.arange(height, device=device, dtype=torch.float32) + 0.5 - height / 2
    col_c = torch.arange(width, device=device, dtype=torch.float32) + 0.5 - width / 2
    below = row_c > 0
    z = torch.where(below, f * camera_height / row_c.clamp(min=1e-6), torch.zeros_like(row_c))
    # A row resolves dashes while its footprint along the road is under half a dash period.
    footprint = f * camera_height / (row_c - 0.5).clamp(min=1e-3) - z
    resolved = below & (footprint < DASH_PERIOD / 2)
    lat = cam_lat.view(-1, 1, 1) + (col_c / f).view(1, 1, width) * z.view(1, height, 1)
    lat_pixel = (z / f).view(1, height, 1).expand_as(lat)
    on_road, solid, dashed = _markings(lat, lat_pixel, lanes, lane_width)
    bg = torch.where(on_road, _colour(ROAD), _colour(VERGE))
    bg = torch.where(solid, _colour(MARKING), bg)
    # Dashes a row cannot resolve show as a faint continuous line of their average brightness.
    faint = _colour(_blend(ROAD, MARKING, DASH_LENGTH / DASH_PERIOD))
    bg = torch.where(dashed, torch.where(resolved.view(1, height, 1), _colour(MARKING), faint), bg)
    t = (row_c.clamp(max=0) / (-height / 2))
    sky = torch.tensor([_colour(_blend(SKY_HORIZON, SKY_TOP, float(x))) for x in t], device=device)
    bg = torch.where(below.view(1, height, 1), bg, sky.view(1, height, 1))
    dashed = dashed & resolved.view(1, height, 1)
    # Only rows that resolve dashes can show a gap: keep the table from the first such row on.
    first = int(resolved.nonzero()[0]) if bool(resolved.any()) else height
    return bg.to(torch.int32), dashed[:, first:].contiguous(), z, resolved, first


def front_camera(sim: HighwaySimulator, state: TrafficState | None = None, *, height: int = 84, width: int = 84,
                 fov_deg: float = 90.0, camera_height: float = 1.4, max_range: float = 150.0) -> torch.Tensor:
    """The host's forward RGB camera, uint8 [N, 3, H, W] (see the module docstring)."""
    s = sim.state if state is None else state
    n = s.pos_lon.shape[0]
    d = s.pos_lon.device
    c = sim.config
    f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    vehicle_height = max(VEHICLE_HEIGHT, camera_height + 0.1)
    half_len, half_wid = sim.half_len_by_type[s.vtype], sim.half_wid_by_type[s.vtype]
    cam_lon = s.pos_lon[:, HOST] + half_len[:, HOST]  # [N]
    cam_lat = s.pos_lat[:, HOST]

    # --- background: table lookup by lateral position, then the dash gaps of this position.
    bg, dashed, z, resolved, first = _front_tables(c.lanes, float(c.lane_width), height, width, float(fov_deg),
                                                   float(camera_height), str(d))
    lat_index = torch.round(cam_lat / LAT_STEP).long().clamp(0, bg.shape[0] - 1)
    gap_row = resolved & (torch.remainder(cam_lon.unsqueeze(1) + z, DASH_PERIOD) >= DASH_LENGTH)  # [N, H]
    road = torch.tensor(int(_colour(ROAD)), dtype=torch.int32, device=d)
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
    r0 = max(0, min(height, math.floor(lo + height / 2)))
    r1 = max(r0, min(height, math.ceil(hi + height / 2)))
    rows = (torch.arange(r0, r1, device=d, dtype=torch.float32) + 0.5 - height / 2).view(1, -1, 1)
    band = image[:, r0:r1]
    band = blend(band, body, (rows >= top_row) & (rows < bumper_row))
    image[:, r0:r1] = blend(band, bumper, (rows >= bumper_row) & (rows < bottom_row))
    return unpack_rgb(image)


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
    on_road, solid, dashed = _markings(lat, torch.full_like(lat, geom.dx), lanes, lane_width)
    row = torch.where(on_road, _colour(ROAD), _colour(VERGE))
    row = torch.where(solid | dashed, _colour(MARKING), row)
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
    image = blend(bg.expand(n, height, width), torch.tensor(int(_colour(ROAD)), dtype=torch.int32, device=d),
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
