"""The top-down picture and the episode videos made from it."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
from PIL import Image, ImageSequence

from baselines.drivers import RandomDriver
from hgm_repro.contracts.config_files import scenario_config, simulator_config
from hgm_repro.envs.render import SHOULDER_M, render_top_down
from hgm_repro.envs.video import record_episode, save_episode
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
