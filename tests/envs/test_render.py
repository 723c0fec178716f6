"""The top-down picture and the episode videos made from it."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
from PIL import Image, ImageSequence

from baselines.drivers import RandomDriver
from hgm_repro.contracts.config_files import observation_config, scenario_config, simulator_config
from hgm_repro.envs.render import (
    BAR,
    CHOSEN,
    HGM_PANEL_W,
    HOST_OUTLINE,
    PANEL,
    SHOULDER_M,
    TITLE_H,
    action_values_panel,
    hgm_colour_limit,
    hgm_panel,
    hgm_picture,
    hgm_plot_box,
    render_top_down,
    render_watch_frame,
)
from hgm_repro.envs.video import record_episode, save_episode
from hgm_repro.observations import ObservationBuilder
from hgm_repro.observations.grid import GridGeometry
from hgm_repro.observations.hyper_grid_matrix import hgm_geometry
from hgm_repro.simulator import HOST, Action, HighwaySimulator


def make_sim(n_envs: int = 2, seed: int = 0, **overrides) -> HighwaySimulator:
    cfg = simulator_config(**overrides)
    return HighwaySimulator(cfg, scenario_config("train", cfg), n_envs, seed=seed)


def count_colour(img: np.ndarray, rgb) -> int:
    return int((img.reshape(-1, 3) == np.asarray(rgb, dtype=np.uint8)).all(1).sum())


def test_picture_has_expected_size_and_is_not_blank():
    sim = make_sim()
    img = render_top_down(sim, behind=60.0, ahead=120.0, px_per_m=5.0)
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert img.shape[1] == round(180 * 5.0)
    road_px = round((sim.config.lanes * sim.config.lane_width + 2 * SHOULDER_M) * 5.0)
    assert img.shape[0] > road_px  # road, shoulders and the text strip
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 50
    assert img.std() > 10


def test_host_colour_present_and_bigger_scale_gives_bigger_picture():
    sim = make_sim()
    host_rgb = sim.state.color[0, HOST].tolist()
    small = render_top_down(sim, px_per_m=4.0)
    big = render_top_down(sim, px_per_m=8.0, action=int(Action.ACCELERATE), caption="test")
    assert count_colour(small, host_rgb) > 0
    # The body is a rectangle of its true size: its interior grows with the square of the scale.
    assert count_colour(big, host_rgb) > 2 * count_colour(small, host_rgb)
    assert big.shape[1] == 2 * small.shape[1]


def test_inactive_vehicles_are_not_drawn_and_env_index_is_checked():
    sim = make_sim()
    s = sim.state
    marker = [0, 0, 255]  # no drawn vehicle colour is pure blue (see _draw_colors)
    s.pos_lon[1, 1] = s.pos_lon[1, HOST] + 20.0
    s.color[1, 1] = torch.tensor(marker, dtype=torch.uint8)
    assert count_colour(render_top_down(sim, env_index=1), marker) > 0
    s.active[1, 1] = False
    assert count_colour(render_top_down(sim, env_index=1), marker) == 0
    with pytest.raises(IndexError):
        render_top_down(sim, env_index=2)


def test_lane_change_in_progress_renders():
    sim = make_sim()
    sim.step(torch.full((2,), int(Action.LANE_LEFT)))
    img = render_top_down(sim, action=int(Action.LANE_LEFT))
    assert count_colour(img, sim.state.color[0, HOST].tolist()) > 0


def test_gif_round_trip_keeps_every_frame(tmp_path):
    sim = make_sim()
    frames = [render_top_down(sim)]
    for _ in range(4):
        sim.step(torch.full((2,), int(Action.ACCELERATE)))
        frames.append(render_top_down(sim))
    path = save_episode(frames, tmp_path / "episode.gif", fps=4)
    with Image.open(path) as gif:
        read = [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(gif)]
    assert len(read) == len(frames)
    assert read[0].shape == frames[0].shape


def test_bad_suffix_and_missing_ffmpeg_fail_clearly(tmp_path):
    frame = np.zeros((8, 8, 3), np.uint8)
    with pytest.raises(ValueError, match="gif"):
        save_episode([frame], tmp_path / "x.avi")
    with pytest.raises(ValueError):
        save_episode([], tmp_path / "x.gif")
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        with pytest.raises(RuntimeError, match=r"\.gif"):
            save_episode([frame], tmp_path / "x.mp4")


def test_record_episode_films_one_env(tmp_path):
    sim = make_sim(n_envs=2, episode_seconds=2.0)  # 4 decisions
    metrics = record_episode(sim, RandomDriver(), tmp_path / "random.gif", max_decisions=10)
    assert sim.host_safety_layer is False  # the driver's choice was applied to the simulator
    with Image.open(tmp_path / "random.gif") as gif:
        n_frames = gif.n_frames
    # The first frame plus one per decision, up to the episode's end (a crash can end it sooner).
    assert 2 <= n_frames <= 5
    assert metrics["decisions"] == n_frames - 1
    assert {"avg_speed_kmh", "lane_changes", "collisions"} <= set(metrics)


# --- the watch frame: what a learned host saw and what it chose ---------------------------------


def _bars(panel: np.ndarray, value_w: int = 80, name_w: int = 110) -> list[tuple[int, int]]:
    """(first, last) column of each action's bar, top to bottom, in an action-values panel."""
    area = panel[:, name_w - 1: panel.shape[1] - value_w]
    is_bar = (area == np.asarray(BAR, np.uint8)).all(-1) | (area == np.asarray(CHOSEN, np.uint8)).all(-1)
    rows = np.flatnonzero(is_bar.any(1))
    bands = np.split(rows, np.flatnonzero(np.diff(rows) > 1) + 1)
    return [(int(np.flatnonzero(is_bar[b].any(0))[0]), int(np.flatnonzero(is_bar[b].any(0))[-1])) for b in bands]


@pytest.mark.parametrize("values", [[-2.0, 1.0, 0.5, -0.5, 3.0], [5.0, 6.0, 7.0, 8.0, 9.0]], ids=["mixed", "positive"])
def test_q_value_bars_are_drawn_from_zero(values):
    q = np.asarray(values)
    bars = _bars(np.asarray(action_values_panel(q, int(q.argmax()), (400, 242))))
    assert len(bars) == len(q)
    # A negative value's bar ends at the zero line and reaches left of it; a positive one starts there.
    zero = [last if v < 0 else first for v, (first, last) in zip(q, bars, strict=True)]
    assert max(zero) - min(zero) <= 2, bars
    for v, (first, last) in zip(q, bars, strict=True):
        assert (first < zero[0] - 5) if v < 0 else (last > zero[0] + 5), (v, first, last)
    # Lengths in proportion to |Q| (not to Q minus the smallest Q).
    lengths = np.asarray([last - first for first, last in bars], float)
    np.testing.assert_allclose(lengths / lengths.max(), np.abs(q) / np.abs(q).max(), atol=0.03)


def _host_marker_centre(panel: np.ndarray, box: tuple[int, int, int, int]) -> tuple[float, float]:
    x0, y0, x1, y1 = box
    ys, xs = np.nonzero((panel[y0 - 4:y1 + 4, x0 - 4:x1 + 4] == np.asarray(HOST_OUTLINE, np.uint8)).all(-1))
    assert xs.size > 0, "the host is not marked in the HGM panel"
    return x0 - 4 + (xs.min() + xs.max()) / 2, y0 - 4 + (ys.min() + ys.max()) / 2


def test_hgm_panel_lies_like_the_top_down_view_and_marks_the_host():
    sim = make_sim(n_envs=1)
    cfg, limit = sim.config, hgm_colour_limit(sim.config)
    window = GridGeometry(height=84, width=84, ahead=40.0, behind=40.0, left=0.0, right=cfg.lanes * cfg.lane_width)
    size = (HGM_PANEL_W, PANEL + TITLE_H)
    box = x0, y0, x1, y1 = hgm_plot_box(window, size)
    # One scale in metres along and across the road, as in the top-down view.
    assert abs((x1 - x0) / 80.0 - (y1 - y0) / window.right) < 0.1
    values = np.zeros((84, 84))
    values[:4, :10] = limit  # a fast vehicle at the far end ahead, at the left road edge
    fast = hgm_picture(np.array([[limit]]), limit)[0, 0]
    for lane, (low, high) in ((0, (y0, y0 + (y1 - y0) / cfg.lanes)), (cfg.lanes - 1, (y1 - (y1 - y0) / cfg.lanes, y1))):
        sim.state.pos_lat[0, HOST] = (lane + 0.5) * cfg.lane_width
        panel = np.asarray(hgm_panel(values, window, sim, 0, limit, size))
        # Forward is to the right and the left road edge at the top: the vehicle ahead on the left is top right.
        plot = (panel[y0:y1, x0:x1] == fast).all(-1)
        ys, xs = np.nonzero(plot)
        assert xs.size and xs.min() > 0.9 * (x1 - x0) and ys.max() < 0.2 * (y1 - y0)
        # The host at 0 m along the road (the middle of a symmetric window), in its lane across it.
        x, y = _host_marker_centre(panel, box)
        assert abs(x - (x0 + x1) / 2) <= 2 and low <= y <= high, (lane, x, y, box)


def test_watch_frame_shows_the_hgm_in_metres_with_the_host():
    sim = make_sim(n_envs=1)
    obs_cfg = observation_config({"camera": "front", "hgm": "paper", "coordinates": False}, hgm_ahead=20.0)
    observation = ObservationBuilder(sim, obs_cfg).reset()
    q = np.array([-1.0, 0.5, 2.0, -0.2, 1.0])
    with pytest.raises(ValueError, match="hgm_window"):
        render_watch_frame(sim, 0, observation, q, 2)
    window = hgm_geometry(sim, obs_cfg.height, obs_cfg.width, obs_cfg.v2x_range, obs_cfg.hgm_ahead)
    frame = render_watch_frame(sim, 0, observation, q, 2, hgm_window=window)
    panel = frame[:PANEL + TITLE_H, PANEL + 4:PANEL + 4 + HGM_PANEL_W]
    x0, y0, x1, y1 = box = hgm_plot_box(window, (HGM_PANEL_W, PANEL + TITLE_H))
    # 40 m behind and 20 m ahead: the host is two thirds of the way along.
    x, _ = _host_marker_centre(panel, box)
    assert abs(x - (x0 + 2 * (x1 - x0) / 3)) <= 2
