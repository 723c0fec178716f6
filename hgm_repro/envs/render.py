"""A top-down picture of one env's road, for people watching an episode (not for the agent).

The road runs left to right in the driving direction, so the driver's left (lane 0) is at the
top. Every active vehicle is drawn at its true size in its own colour; the host gets a thick
outline, and vehicles that send V2X data carry a small white antenna dot. Clarity comes before
speed here: this draws one env with PIL, once per frame.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ..simulator.highway import HighwaySimulator
from ..simulator.state import HOST, Action

GRASS = (86, 118, 72)
ASPHALT = (72, 72, 76)
MARKING = (235, 235, 235)
STRIP = (24, 24, 28)
TEXT = (240, 240, 240)
HOST_OUTLINE = (255, 220, 40)
VEHICLE_OUTLINE = (20, 20, 20)
V2X_BAND = (110, 160, 220)
DASH_M, DASH_GAP_M = 3.0, 9.0  # a common motorway dash pattern
SHOULDER_M = 2.0
SUPERSAMPLE = 2


@lru_cache(maxsize=4)
def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow built without FreeType: the fixed bitmap font still reads well
        return ImageFont.load_default()


def render_top_down(sim: HighwaySimulator, env_index: int = 0, behind: float = 60.0, ahead: float = 120.0,
                    px_per_m: float = 6.0, action: int | None = None, v2x_range: float | None = 40.0,
                    caption: str | None = None) -> np.ndarray:
    """RGB picture [h, w, 3] uint8 of env `env_index`, `behind` m behind the host to `ahead` m ahead.

    `action` is the host's last decision (shown in the text strip when given); `v2x_range` shades
    the band of road within D_r of the host (None hides it); `caption` adds free text to the strip.
    """
    if not 0 <= env_index < sim.n_envs:
        raise IndexError(f"env_index={env_index} is outside 0..{sim.n_envs - 1}")
    cfg = sim.config
    s = sim.state.select_env(env_index).to("cpu")
    pos_lon = s.pos_lon[0].double().numpy()
    pos_lat = s.pos_lat[0].double().numpy()
    speed = s.speed[0].double().numpy()
    target_lane = s.target_lane[0].numpy()
    vtype = s.vtype[0].numpy()
    active = s.active[0].numpy()
    color = s.color[0].numpy()
    half_len = sim.half_len_by_type.cpu().double().numpy()[vtype]
    half_wid = sim.half_wid_by_type.cpu().double().numpy()[vtype]
    connected = sim.connected_by_type.cpu().numpy()[vtype]
    v_lat = sim.v_lat_by_type.cpu().double().numpy()[vtype]
    centres = sim.lane_centres.cpu().double().numpy()

    # Drawn at SUPERSAMPLE times the size and shrunk at the end: tilted bodies and text come
    # out anti-aliased instead of stair-stepped.
    out_strip_h = max(18, int(round(3.6 * px_per_m)))
    road_w = cfg.lanes * cfg.lane_width
    out_w = int(round((behind + ahead) * px_per_m))
    out_h = out_strip_h + int(round((road_w + 2 * SHOULDER_M) * px_per_m))
    px_per_m = px_per_m * SUPERSAMPLE
    strip_h, width, height = out_strip_h * SUPERSAMPLE, out_w * SUPERSAMPLE, out_h * SUPERSAMPLE
    font = _font(max(11, int(round(2.2 * px_per_m))))
    x_host = pos_lon[HOST]
    x_left = x_host - behind

    def px(lon: np.ndarray | float) -> np.ndarray | float:
        return (lon - x_left) * px_per_m

    def py(lat: np.ndarray | float) -> np.ndarray | float:
        return strip_h + (lat + SHOULDER_M) * px_per_m

    img = Image.new("RGB", (width, height), GRASS)
    draw = ImageDraw.Draw(img, "RGBA")
    draw.rectangle([0, py(0.0), width, py(road_w)], fill=ASPHALT)
    if v2x_range is not None:
        # The band the host hears V2X from (Alg. 1 tests |y_i - y_0| < D_r along the road).
        draw.rectangle([px(x_host - v2x_range), py(0.0), px(x_host + v2x_range), py(road_w)],
                       fill=(*V2X_BAND, 40))

    # Solid edges; dashed lane lines anchored to the road (absolute position) so they slide
    # past the host and show its speed.
    line_w = max(1, int(round(0.15 * px_per_m)))
    for lat in (0.0, road_w):
        draw.line([(0, py(lat)), (width, py(lat))], fill=MARKING, width=line_w)
    period = DASH_M + DASH_GAP_M
    first = math.floor(x_left / period) * period
    dash_starts = np.arange(first, x_host + ahead + period, period)
    for k in range(1, cfg.lanes):
        y = py(k * cfg.lane_width)
        for x0 in dash_starts:
            draw.line([(px(x0), y), (px(x0 + DASH_M), y)], fill=MARKING, width=line_w)

    # Vehicles: host last so that it is never hidden.
    order = [i for i in range(len(pos_lon)) if active[i] and i != HOST] + [HOST]
    for i in order:
        if pos_lon[i] + half_len[i] < x_left or pos_lon[i] - half_len[i] > x_host + ahead:
            continue
        # Tilt the body while it changes lanes: heading from lateral and longitudinal speed.
        d_lat = centres[target_lane[i]] - pos_lat[i]
        lat_speed = 0.0 if abs(d_lat) < 1e-3 else math.copysign(v_lat[i], d_lat)
        heading = math.atan2(lat_speed, max(speed[i], 1e-3))
        c, sn = math.cos(heading), math.sin(heading)
        corners = []
        for dx, dy in ((half_len[i], half_wid[i]), (half_len[i], -half_wid[i]),
                       (-half_len[i], -half_wid[i]), (-half_len[i], half_wid[i])):
            corners.append((px(pos_lon[i] + dx * c - dy * sn), py(pos_lat[i] + dx * sn + dy * c)))
        if i == HOST:
            # A halo around the body keeps the host's own colour visible inside it.
            m = 0.6
            halo = [(px(pos_lon[i] + dx * c - dy * sn), py(pos_lat[i] + dx * sn + dy * c))
                    for dx, dy in ((half_len[i] + m, half_wid[i] + m), (half_len[i] + m, -half_wid[i] - m),
                                   (-half_len[i] - m, -half_wid[i] - m), (-half_len[i] - m, half_wid[i] + m))]
            draw.polygon(halo, fill=HOST_OUTLINE)
        draw.polygon(corners, fill=tuple(int(v) for v in color[i]), outline=VEHICLE_OUTLINE, width=1)
        # A darker windscreen at the front tells the driving direction at a glance.
        wx = pos_lon[i] + 0.45 * half_len[i]
        ws = [(px(wx + dx * c - dy * sn), py(pos_lat[i] + dx * sn + dy * c))
              for dx, dy in ((0.25 * half_len[i], 0.7 * half_wid[i]), (0.25 * half_len[i], -0.7 * half_wid[i]),
                             (0.0, -0.7 * half_wid[i]), (0.0, 0.7 * half_wid[i]))]
        draw.polygon(ws, fill=(0, 0, 0, 110))
        if connected[i]:
            r = max(2.0, 0.35 * px_per_m)
            ax, ay = px(pos_lon[i] - 0.35 * half_len[i]), py(pos_lat[i])
            draw.ellipse([ax - r, ay - r, ax + r, ay + r], fill=(255, 255, 255), outline=(0, 0, 0))

    # Text strip: what a person wants while watching.
    draw.rectangle([0, 0, width, strip_h - 1], fill=STRIP)
    host_lane = int(target_lane[HOST])
    parts = [f"{speed[HOST] * 3.6:5.1f} km/h", f"lane {host_lane} (0 = left)",
             f"t {int(s.decision[0]) * cfg.decision_dt:5.1f} s"]
    if action is not None:
        parts.append(f"decision: {Action(int(action)).name.lower().replace('_', ' ')}")
    if caption:
        parts.append(caption)
    draw.text((6, strip_h / 2), "   |   ".join(parts), fill=TEXT, font=font, anchor="lm")
    return np.asarray(img.resize((out_w, out_h), Image.Resampling.LANCZOS), dtype=np.uint8)
