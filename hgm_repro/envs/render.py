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

from ..observations.grid import GridGeometry
from ..observations.hyper_grid_matrix import decode_hgm
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
                    caption: str | None = None, legend: bool = True) -> np.ndarray:
    """RGB picture [h, w, 3] uint8 of env `env_index`, `behind` m behind the host to `ahead` m ahead.

    `action` is the host's last decision (shown in the text strip when given); `v2x_range` shades
    the band of road within D_r of the host (None hides it); `caption` adds free text to the strip;
    `legend` adds a strip below the road that says what the colours, dots and band mean.
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
    road_h = out_strip_h + int(round((road_w + 2 * SHOULDER_M) * px_per_m))
    out_h = road_h + (out_strip_h if legend else 0)
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
    if legend:
        _legend(draw, road_h * SUPERSAMPLE, width, strip_h, font, px_per_m, v2x_range is not None)
    return np.asarray(img.resize((out_w, out_h), Image.Resampling.LANCZOS), dtype=np.uint8)


def _legend(draw: ImageDraw.ImageDraw, top: float, width: float, strip_h: float, font, px_per_m: float,
            band: bool) -> None:
    """Below the road: the host's look, the V2X dot, the shaded band; other colours mean nothing."""
    draw.rectangle([0, top, width, top + strip_h], fill=STRIP)
    y, box, x = top + strip_h / 2, strip_h * 0.32, 8.0

    def label(text: str) -> None:
        nonlocal x
        draw.text((x, y), text, fill=TEXT, font=font, anchor="lm")
        x += draw.textlength(text, font=font) + 3 * box

    draw.rectangle([x - 2, y - box - 2, x + 2 * box + 2, y + box + 2], fill=HOST_OUTLINE)
    draw.rectangle([x, y - box, x + 2 * box, y + box], fill=(230, 30, 30))
    x += 2 * box + 8
    label("host (red, yellow rim)")
    r = max(2.0, 0.35 * px_per_m)
    draw.ellipse([x - r, y - r, x + r, y + r], fill=(255, 255, 255), outline=(0, 0, 0))
    x += r + 8
    label("connected: sends V2X")
    if band:
        draw.rectangle([x, y - box, x + 3 * box, y + box], fill=tuple(int(0.3 * b + 0.7 * a) for a, b in
                                                                         zip(ASPHALT, V2X_BAND, strict=True)))
        x += 3 * box + 8
        label("V2X range of the host (the HGM's view)")
    label("other colours: random, one per car")


# --- watching a learned host: what it saw, what it chose, and the road ---------------------

PANEL_BG = (16, 16, 20)
CHOSEN = (255, 220, 40)
BAR = (120, 150, 190)
AXIS = (150, 150, 158)
PANEL = 224  # px, the side of the camera panel and the height of the top row's panels
TITLE_H = 18
HGM_PANEL_W = 480  # px: the HGM panel is wide, since it lies along the road like the top-down view
HGM_MARGIN = (40, 10, 44, 46)  # px around the HGM's plot: left (across ticks), right, top, bottom (ticks, bar)


def hgm_colour_limit(sim_config) -> float:
    """|cell value| of a vehicle at v_min or v_max: the HGM's colour scale runs over +-this.
    Values lie in +-(v_max - v_mid) / v_mid for vehicles within the speed limits."""
    v_mid = (sim_config.v_max + sim_config.v_min) / 2
    return (sim_config.v_max - v_mid) / v_mid


def hgm_picture(values: np.ndarray, limit: float) -> np.ndarray:
    """HGM cell values [H, W] (decoded) as an RGB picture, blue slower and red faster than v_mid."""
    from matplotlib import colormaps

    scaled = np.clip((values + limit) / (2 * limit), 0.0, 1.0)
    return (colormaps["RdBu_r"](scaled)[..., :3] * 255).astype(np.uint8)


def _titled(picture: np.ndarray, title: str, size: tuple[int, int]) -> Image.Image:
    """`picture` scaled (nearest: the network's pixels stay visible) under a title line."""
    w, h = size
    panel = Image.new("RGB", (w, h + TITLE_H), PANEL_BG)
    panel.paste(Image.fromarray(picture).resize((w, h), Image.Resampling.NEAREST), (0, TITLE_H))
    ImageDraw.Draw(panel).text((4, TITLE_H / 2), title, fill=TEXT, font=_font(12), anchor="lm")
    return panel


def hgm_plot_box(window: GridGeometry, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """(left, top, right, bottom) px of the HGM's plot inside its panel of `size`: one scale in metres
    along and across the road (as in the top-down view), as large as the panel's margins allow."""
    left, right, top, bottom = HGM_MARGIN[0], size[0] - HGM_MARGIN[1], HGM_MARGIN[2], size[1] - HGM_MARGIN[3]
    along, across = window.ahead + window.behind, window.right - window.left
    px_per_m = min((right - left) / along, (bottom - top) / across)
    plot_w, plot_h = int(round(along * px_per_m)), int(round(across * px_per_m))
    left, top = left + (right - left - plot_w) // 2, top + (bottom - top - plot_h) // 2
    return left, top, left + plot_w, top + plot_h


def hgm_panel(values: np.ndarray, window: GridGeometry, sim: HighwaySimulator, env_index: int, limit: float,
              size: tuple[int, int]) -> Image.Image:
    """The HGM the network read, turned to lie like the top-down view: forward to the right, the left road
    edge at the top, in metres from the host along the road and from the left edge across it; the host's
    box outlined as in the top-down view; below, the colour scale in km/h.

    `values`: decoded cell values [H, W] (row 0 farthest ahead, column 0 at the left edge); `window`: the
    grid's extent (`hyper_grid_matrix.hgm_geometry`)."""
    panel = Image.new("RGB", size, PANEL_BG)
    draw = ImageDraw.Draw(panel)
    font = _font(11)
    draw.text((4, TITLE_H / 2), f"HGM {values.shape[0]}x{values.shape[1]} (input), as on the road below",
              fill=TEXT, font=_font(12), anchor="lm")
    x0, y0, x1, y1 = hgm_plot_box(window, size)
    # Clockwise a quarter turn: rows along the road become columns, ahead on the right.
    picture = np.ascontiguousarray(np.rot90(hgm_picture(values, limit), k=-1))
    panel.paste(Image.fromarray(picture).resize((x1 - x0, y1 - y0), Image.Resampling.NEAREST), (x0, y0))

    def px(lon: float) -> float:
        return x0 + (lon + window.behind) / (window.ahead + window.behind) * (x1 - x0)

    def py(lat: float) -> float:
        return y0 + (lat - window.left) / (window.right - window.left) * (y1 - y0)

    cfg = sim.config
    for k in range(1, cfg.lanes):  # lane lines, faint: the cells themselves carry the information
        y = py(k * cfg.lane_width)
        for x in np.arange(x0, x1, 6.0):
            draw.line([(x, y), (min(x + 2, x1), y)], fill=AXIS)
    draw.rectangle([x0 - 1, y0 - 1, x1, y1], outline=AXIS)
    # Along the road: metres from the host, forward to the right.
    step = 20.0 if window.ahead + window.behind >= 60 else 10.0
    for lon in np.arange(-np.floor(window.behind / step) * step, window.ahead + 1e-6, step):
        x = px(lon)
        draw.line([(x, y1), (x, y1 + 3)], fill=AXIS)
        draw.text((x, y1 + 4), f"{lon:+.0f}" if lon else "0", fill=TEXT, font=font, anchor="mt")
    label_y = y1 + 22
    draw.text((x0, label_y), "m from the host along the road", fill=TEXT, font=font, anchor="lm")
    arrow_x = x1 - 6
    draw.text((arrow_x - 22, label_y), "forward", fill=TEXT, font=font, anchor="rm")
    draw.line([(arrow_x - 18, label_y), (arrow_x, label_y)], fill=TEXT, width=2)
    draw.polygon([(arrow_x + 2, label_y), (arrow_x - 5, label_y - 4), (arrow_x - 5, label_y + 4)], fill=TEXT)
    # Across the road: metres from the left road edge (lane 0 at the top, as in the top-down view).
    for lat in np.arange(window.left, window.right + 1e-6, 5.0):
        y = py(lat)
        draw.line([(x0 - 4, y), (x0 - 1, y)], fill=AXIS)
        draw.text((x0 - 6, y), f"{lat:.0f}", fill=TEXT, font=font, anchor="rm")
    draw.text((x0 - 6, y0 - 8), "m from the left road edge", fill=TEXT, font=font, anchor="ls")
    # The host: its collision box at 0 m, outlined in the top-down view's host colour.
    s = sim.state.select_env(env_index).to("cpu")
    vtype = int(s.vtype[0, HOST])
    half_len, half_wid = float(sim.half_len_by_type[vtype]), float(sim.half_wid_by_type[vtype])
    lat = float(s.pos_lat[0, HOST])
    draw.rectangle([px(-half_len) - 2, py(lat - half_wid) - 2, px(half_len) + 2, py(lat + half_wid) + 2],
                   outline=HOST_OUTLINE, width=2)
    # The colour scale: a cell's value is its vehicle's speed relative to v_mid.
    v_mid = (cfg.v_max + cfg.v_min) / 2
    bar_top, bar_w = y1 + 34, min(180, x1 - x0)
    high_text = f"{v_mid * (1 + limit) * 3.6:.0f} km/h"
    bar_x = int(x1 - draw.textlength(high_text, font=font) - 4 - bar_w)
    ramp = hgm_picture(np.linspace(-limit, limit, bar_w)[None, :], limit)
    panel.paste(Image.fromarray(np.repeat(ramp, 8, axis=0)), (bar_x, bar_top))
    draw.text((bar_x - 4, bar_top + 4), f"cell = its vehicle's speed: {v_mid * (1 - limit) * 3.6:.0f}",
              fill=TEXT, font=font, anchor="rm")
    draw.text((bar_x + bar_w + 4, bar_top + 4), high_text, fill=TEXT, font=font, anchor="lm")
    draw.text((bar_x + bar_w / 2, bar_top + 10), f"{v_mid * 3.6:.0f} (or empty)", fill=TEXT, font=font,
              anchor="mt")
    return panel


def action_values_panel(action_values: np.ndarray, chosen: int | None, size: tuple[int, int]) -> Image.Image:
    """One row per action: its name, a bar from 0 to its Q-value (left of the zero line when negative), the
    value; the chosen one highlighted."""
    w, h = size
    panel = Image.new("RGB", (w, h), PANEL_BG)
    draw = ImageDraw.Draw(panel)
    font = _font(13)
    draw.text((6, TITLE_H / 2), "Q-values (greedy: the largest is chosen)", fill=TEXT, font=_font(12), anchor="lm")
    lo, hi = min(float(action_values.min()), 0.0), max(float(action_values.max()), 0.0)
    span = max(hi - lo, 1e-6)
    name_w, value_w, axis_h = 110, 80, 16
    bar_w = w - name_w - value_w - 12
    row_h = (h - TITLE_H - 6 - axis_h) / len(action_values)

    def px(q: float) -> float:
        return name_w + bar_w * (q - lo) / span

    for a, q in enumerate(action_values):
        y = TITLE_H + 3 + a * row_h
        colour = CHOSEN if a == chosen else TEXT
        name = Action(a).name.lower().replace("_", " ")
        draw.text((6, y + row_h / 2), ("> " if a == chosen else "  ") + name, fill=colour, font=font, anchor="lm")
        ends = sorted((px(0.0), px(float(q))))
        draw.rectangle([ends[0], y + row_h * 0.2, ends[1], y + row_h * 0.8], fill=CHOSEN if a == chosen else BAR)
        draw.text((w - 6, y + row_h / 2), f"{float(q):+.3f}", fill=colour, font=font, anchor="rm")
    bottom = TITLE_H + 3 + len(action_values) * row_h
    draw.line([(px(0.0), TITLE_H + 3), (px(0.0), bottom + 2)], fill=AXIS)
    draw.text((px(0.0), bottom + 3), "0", fill=TEXT, font=_font(11), anchor="mt")
    return panel


def render_watch_frame(sim: HighwaySimulator, env_index: int, observation: dict, action_values: np.ndarray,
                       action: int | None, caption: str | None = None, hgm_limit: float | None = None,
                       hgm_window: GridGeometry | None = None, **top_down_kwargs) -> np.ndarray:
    """One frame of a learned host driving: top row the network's inputs (the newest camera frame
    and HGM of its stacks) and its Q-values with the chosen action; below, the top-down view.

    `observation`: the stacked observations the network read (`camera`, `hgm` uint8 [N, 3F, H, W],
    only the streams the model has); `action_values`: its Q-values [5] for env `env_index`;
    `hgm_window`: the HGM's extent around the host (`hyper_grid_matrix.hgm_geometry`), needed to draw it
    in metres.
    """
    top = render_top_down(sim, env_index, action=action, caption=caption, **top_down_kwargs)
    panels: list[Image.Image] = []
    if "camera" in observation:
        camera = observation["camera"][env_index, -3:].permute(1, 2, 0).cpu().numpy()
        panels.append(_titled(camera, f"camera {camera.shape[0]}x{camera.shape[1]} (input)", (PANEL, PANEL)))
    if "hgm" in observation:
        if hgm_window is None:
            raise ValueError("render_watch_frame needs hgm_window (hgm_geometry of the observation config) "
                             "to draw the HGM in metres")
        values = decode_hgm(observation["hgm"][env_index, -3]).cpu().numpy()
        limit = hgm_limit if hgm_limit is not None else hgm_colour_limit(sim.config)
        panels.append(hgm_panel(values, hgm_window, sim, env_index, limit, (HGM_PANEL_W, PANEL + TITLE_H)))
    gap = 4
    width = top.shape[1]
    used = sum(p.width + gap for p in panels)
    panels.append(action_values_panel(np.asarray(action_values, dtype=np.float64), action,
                                      (max(width - used, 260), PANEL + TITLE_H)))
    row_w = sum(p.width for p in panels) + gap * (len(panels) - 1)
    frame = Image.new("RGB", (max(row_w, width), PANEL + TITLE_H + gap + top.shape[0]), PANEL_BG)
    x = 0
    for panel in panels:
        frame.paste(panel, (x, 0))
        x += panel.width + gap
    frame.paste(Image.fromarray(top), (0, PANEL + TITLE_H + gap))
    return np.asarray(frame, dtype=np.uint8)
