"""The observation builders on hand-built states: HGM (Algorithm 1), camera, coordinates, stacks."""

from __future__ import annotations

import pytest
import torch
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hgm_repro.contracts.config_files import observation_config, observation_node, scenario_config, simulator_config
from hgm_repro.observations import (
    FrameStack,
    ObservationBuilder,
    ObservationConfig,
    birdseye_camera,
    coordinates,
    decode_hgm,
    encode_hgm,
    front_camera,
    hyper_grid_matrix,
)
from hgm_repro.simulator import HOST, HighwaySimulator

H = W = 84
D_R = 40.0


def make_sim(n_envs: int = 2, scenario: str = "train", seed: int = 0) -> HighwaySimulator:
    cfg = simulator_config()
    return HighwaySimulator(cfg, scenario_config(scenario, cfg), n_envs, seed=seed)


def empty_road(sim: HighwaySimulator, host_lane: int = 2, host_speed: float = 60 / 3.6) -> HighwaySimulator:
    """Every NPC made inactive; the host alone in `host_lane` at lon 0."""
    s = sim.state
    s.active[:] = False
    s.active[:, HOST] = True
    s.pos_lon[:, HOST] = 0.0
    s.pos_lat[:, HOST] = float(sim.lane_centres[host_lane])
    s.target_lane[:, HOST] = host_lane
    s.speed[:, HOST] = host_speed
    return sim


def place(sim: HighwaySimulator, slot: int, lon: float, lane: int | float, type_name: str = "NCV",
          speed: float = 15.0, env: int | slice = slice(None), color: tuple[int, int, int] | None = None) -> None:
    s = sim.state
    lat = float(sim.lane_centres[lane]) if isinstance(lane, int) else float(lane)
    s.active[env, slot] = True
    s.pos_lon[env, slot] = lon
    s.pos_lat[env, slot] = lat
    s.speed[env, slot] = speed
    s.vtype[env, slot] = sim.config.type_index(type_name)
    if color is not None:
        s.color[env, slot] = torch.tensor(color, dtype=torch.uint8)


def reference_hgm(sim: HighwaySimulator, env: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Algorithm 1 written the plain way for one env (dense over vehicles, fine in a test):
    values [H, W] and the winning slot per cell (-1 empty); host first, then nearest wins."""
    s, c = sim.state, sim.config
    lon0 = s.pos_lon[env, HOST]
    dy, dx = 2 * D_R / H, c.lanes * c.lane_width / W
    rows = D_R - (torch.arange(H, dtype=torch.float32) + 0.5) * dy
    cols = (torch.arange(W, dtype=torch.float32) + 0.5) * dx
    mid = (c.v_max + c.v_min) / 2
    values = torch.zeros(H, W)
    winner = torch.full((H, W), -1)
    best = torch.full((H, W), float("inf"))
    for i in range(s.n_vehicles):
        vt = int(s.vtype[env, i])
        rel = s.pos_lon[env, i] - lon0
        if not (bool(s.active[env, i]) and bool(sim.connected_by_type[vt]) and abs(float(rel)) < D_R):
            continue
        hl, hw = sim.half_len_by_type[vt], sim.half_wid_by_type[vt]
        covered = ((rows - rel).abs() < hl).view(H, 1) & ((cols - s.pos_lat[env, i]).abs() < hw).view(1, W)
        prio = -1.0 if i == HOST else abs(float(rel))
        take = covered & (prio < best)
        best = torch.where(take, torch.tensor(prio), best)
        winner = torch.where(take, torch.tensor(i), winner)
        values = torch.where(take, (s.speed[env, i] - mid) / mid, values)
    return values, winner


def occupancy(sim: HighwaySimulator) -> torch.Tensor:
    return hyper_grid_matrix(sim, variant="enriched")[:, 1] > 0


# ----------------------------------------------------------------------------- HGM
def test_range_is_strict_39_in_41_out():
    sim = empty_road(make_sim())
    place(sim, 1, 39.0, 0)
    occ = occupancy(sim)
    lane0 = slice(0, W // 5)
    assert occ[0, :, lane0].any(), "a connected vehicle 39 m ahead must appear"
    sim.state.pos_lon[:, 1] = 41.0
    assert not occupancy(sim)[0, :, lane0].any(), "a vehicle 41 m ahead is out of V2X range"
    sim.state.pos_lon[:, 1] = -39.0
    assert occupancy(sim)[0, :, lane0].any()
    sim.state.pos_lon[:, 1] = -41.0
    assert not occupancy(sim)[0, :, lane0].any()


def test_forward_is_up_and_left_is_left():
    sim = empty_road(make_sim())
    place(sim, 1, 20.0, 0)
    occ = occupancy(sim)[0]
    rows = occ[:, : W // 5].any(1).nonzero().flatten()
    assert rows.max() < H // 2, "a vehicle ahead is drawn in the upper half"


@pytest.mark.parametrize("type_name", ["CHV", "AHV"])
def test_human_driven_vehicles_never_appear(type_name):
    sim = empty_road(make_sim())
    host_only = occupancy(sim).clone()
    place(sim, 1, 10.0, 1, type_name)
    place(sim, 2, -5.0, 3, type_name)
    assert torch.equal(occupancy(sim), host_only)


@pytest.mark.parametrize("scenario", ["1", "2", "3", "4", "5", "train"])
def test_only_connected_vehicles_appear_in_traffic(scenario):
    sim = make_sim(n_envs=3, scenario=scenario, seed=1)
    sim.host_safety_layer = True
    for _ in range(5):
        sim.step(sim.npc_actions(sim.state)[:, HOST])
    full = hyper_grid_matrix(sim, variant="enriched")
    # Removing every non-connected vehicle must change nothing.
    sim.state.active &= sim.connected_by_type[sim.state.vtype]
    assert torch.equal(hyper_grid_matrix(sim, variant="enriched"), full)


def test_scenario_1_grid_holds_only_the_host():
    sim = make_sim(n_envs=4, scenario="1", seed=2)
    sim.host_safety_layer = True
    for _ in range(3):
        sim.step(sim.npc_actions(sim.state)[:, HOST])
    g = hyper_grid_matrix(sim, variant="enriched")
    assert torch.equal(g[:, 1] > 0, g[:, 2] > 0), "every occupied cell is a host cell"
    assert (g[:, 2] > 0).flatten(1).any(1).all()


def test_cell_value_is_the_papers_formula():
    sim = empty_road(make_sim(), host_speed=22.0)
    place(sim, 1, 15.0, 4, speed=12.0)
    values, winner = reference_hgm(sim)
    mid = (sim.config.v_max + sim.config.v_min) / 2
    g = hyper_grid_matrix(sim)[0, 0]
    assert torch.allclose(g[winner == HOST], torch.tensor((22.0 - mid) / mid))
    assert torch.allclose(g[winner == 1], torch.tensor((12.0 - mid) / mid))
    assert (g[winner == -1] == 0).all()
    paper = hyper_grid_matrix(sim, variant="paper")
    assert torch.equal(paper[:, 0], paper[:, 1]) and torch.equal(paper[:, 0], paper[:, 2])


def test_paper_host_cell_is_empty_at_60_kmh_and_own_range_is_not():
    # Every host starts at 60 km/h, the mid speed, where Algorithm 1 writes 0: the empty cell's value.
    sim = empty_road(make_sim(), host_speed=60 / 3.6)
    place(sim, 1, 15.0, 4, speed=sim.config.v_min)  # the lowest value another vehicle can write
    _, winner = reference_hgm(sim)
    paper = hyper_grid_matrix(sim, encoded=True)[0, 0]
    assert (paper[winner == HOST] == 128).all() and (paper[winner == -1] == 128).all()
    own = hyper_grid_matrix(sim, encoded=True, host_cell="own_range")[0, 0]
    host_code, lowest_other = int(own[winner == HOST].max()), int(own[winner == 1].min())
    assert host_code < lowest_other and host_code != 128
    assert torch.equal(own[winner != HOST], paper[winner != HOST])  # everyone else as the paper draws them
    codes = []  # and the host's speed still reads off its cell, from v_min to v_max
    for kmh in (40, 50, 60, 70, 80):
        sim.state.speed[:, HOST] = kmh / 3.6
        codes.append(int(hyper_grid_matrix(sim, encoded=True, host_cell="own_range")[0, 0][winner == HOST].max()))
    assert codes == sorted(codes) and len(set(codes)) == 5 and codes[0] == 0 and codes[-1] < lowest_other


def test_hgm_ahead_reaches_further_ahead_but_not_behind():
    sim = empty_road(make_sim())
    place(sim, 1, 55.0, 0)
    place(sim, 2, -55.0, 4)
    lane0, lane4 = slice(0, W // 5), slice(4 * W // 5, W)
    paper = hyper_grid_matrix(sim, variant="enriched")[0, 1] > 0
    ahead = hyper_grid_matrix(sim, variant="enriched", ahead=80.0)[0, 1] > 0
    assert not paper[:, lane0].any() and ahead[:, lane0].any()
    assert not ahead[:, lane4].any()  # 55 m behind stays out of the 40 m reach behind
    # The host's own row moves down: 80 m ahead and 40 m behind on the same 84 rows.
    host_rows = ahead[:, W // 2].nonzero().squeeze(1).float().mean()
    assert float(host_rows) == pytest.approx(H * 80 / 120, abs=2)


def test_covered_cells_match_the_collision_box():
    sim = empty_road(make_sim())
    place(sim, 1, 7.3, 1.9)  # between lanes, at an arbitrary offset
    g = hyper_grid_matrix(sim, variant="enriched")[0]
    _, winner = reference_hgm(sim)
    assert torch.equal(g[1] > 0, winner >= 0)
    assert torch.equal(g[2] > 0, winner == HOST)
    # A 4.5 m x 1.8 m box on a 80/84 m x 17.5/84 m grid covers 4..5 rows and 8..9 columns.
    cells = winner == 1
    n_rows, n_cols = cells.any(1).sum().item(), cells.any(0).sum().item()
    assert n_rows in (4, 5) and n_cols in (8, 9)
    assert cells.sum().item() == n_rows * n_cols


def test_overlap_host_then_nearest_wins():
    sim = empty_road(make_sim())
    place(sim, 1, 1.0, 2, speed=11.0)  # overlaps the host (a collision)
    place(sim, 2, 5.0, 2, speed=20.0)  # overlaps vehicle 1
    values, winner = reference_hgm(sim)
    g = hyper_grid_matrix(sim)[0, 0]
    assert torch.allclose(g, values)
    assert (winner == HOST).any() and (winner == 1).any() and (winner == 2).any()


def test_encode_decode_roundtrip():
    v = torch.linspace(-1, 1, 1001)
    x = encode_hgm(v)
    assert x.dtype == torch.uint8 and x[0] == 0 and x[-1] == 255
    assert (decode_hgm(x) - v).abs().max() <= 1 / 255 + 1e-6


def test_encoded_path_equals_encoding_the_float_path():
    sim = make_sim(n_envs=4, seed=3)
    for variant in ("paper", "enriched"):
        assert torch.equal(hyper_grid_matrix(sim, variant=variant, encoded=True),
                           encode_hgm(hyper_grid_matrix(sim, variant=variant)))


@st.composite
def random_states(draw):
    n_cars = draw(st.integers(0, 8))
    cars = [(draw(st.floats(-60, 60)), draw(st.floats(0.5, 17.0)), draw(st.floats(0, 25)),
             draw(st.sampled_from(["NCV", "CHV", "AHV"])), draw(st.booleans())) for _ in range(n_cars)]
    host = (draw(st.floats(0.9, 16.6)), draw(st.floats(5, 25)))
    return host, cars


_SIM = make_sim(n_envs=1)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_states())
# Two vehicles at the same distance from the host overlap with different speeds: the lower slot wins.
@example(((2.0, 5.0), [(0.0, 2.0, 0.0, "NCV", True), (0.0, 1.0, 1.0, "NCV", True), (0.0, 1.0, 0.0, "NCV", True)]))
def test_hgm_matches_reference_on_random_states(case):
    (host_lat, host_speed), cars = case
    sim = _SIM
    empty_road(sim, host_speed=host_speed)
    sim.state.pos_lat[:, HOST] = host_lat
    for i, (lon, lat, speed, type_name, active) in enumerate(cars, start=1):
        place(sim, i, lon, lat, type_name, speed)
        sim.state.active[:, i] = active
    values, winner = reference_hgm(sim)
    g = hyper_grid_matrix(sim, variant="enriched")[0]
    assert torch.allclose(g[0], values, atol=1e-6)
    assert torch.equal(g[1] > 0, winner >= 0)
    assert g.abs().max() <= 1.0
    # Only active connected vehicles (and the host) win cells.
    for slot in winner.unique().tolist():
        if slot >= 0:
            assert bool(sim.state.active[0, slot]) and bool(sim.connected_by_type[sim.state.vtype[0, slot]])


# ----------------------------------------------------------------------------- camera
def vehicle_pixels(sim: HighwaySimulator, **kw) -> torch.Tensor:
    """[N, H, W] pixels that differ from the same scene without NPCs."""
    img = front_camera(sim, **kw)
    active = sim.state.active.clone()
    sim.state.active[:, 1:] = False
    bg = front_camera(sim, **kw)
    sim.state.active[:] = active
    return (img != bg).any(1)


def test_vehicle_ahead_is_centred_and_grows_when_closer():
    sim = empty_road(make_sim())
    widths, heights = [], []
    for lon in (40.0, 20.0, 10.0):
        place(sim, 1, lon, 2, "CHV")
        px = vehicle_pixels(sim)[0]
        cols = px.any(0).nonzero().flatten().float()
        assert cols.numel() > 0
        assert abs((cols.min() + cols.max()) / 2 - (W - 1) / 2) <= 1.0
        widths.append(cols.numel())
        rows = px.any(1).nonzero().flatten()
        assert rows.min() <= H // 2 <= rows.max(), "a car taller than the camera reaches the horizon"
        heights.append(rows.numel())
    assert widths[0] < widths[1] < widths[2]
    assert heights[0] < heights[1] < heights[2]


@pytest.mark.parametrize("lon,lane", [(-10.0, 2), (0.0, 1), (2.0, 3), (-30.0, 0)])
def test_vehicle_behind_or_beside_never_appears(lon, lane):
    sim = empty_road(make_sim())
    place(sim, 1, lon, lane, "CHV")
    assert not vehicle_pixels(sim).any()


def test_nearer_vehicle_hides_farther_one_in_same_lane():
    sim = empty_road(make_sim())
    place(sim, 1, 12.0, 2, "CHV", color=(250, 20, 20))
    place(sim, 2, 25.0, 2, "CHV", color=(20, 20, 250))
    img = front_camera(sim)[0].int()
    blue = (img[2] > 200) & (img[0] < 60)
    assert not blue.any(), "the farther (blue) car is hidden"
    # Alone, the far car is visible.
    sim.state.active[:, 1] = False
    img = front_camera(sim)[0].int()
    assert ((img[2] > 200) & (img[0] < 60)).any()


def test_camera_colour_does_not_depend_on_type():
    sim = empty_road(make_sim())
    place(sim, 1, 15.0, 2, "CHV", color=(200, 100, 50))
    place(sim, 2, 30.0, 3, "AHV", color=(50, 200, 100))
    a = front_camera(sim)
    sim.state.vtype[:, 1:3] = sim.config.type_index("NCV")
    assert torch.equal(front_camera(sim), a)
    assert torch.equal(birdseye_camera(sim), birdseye_camera(sim))


def test_birdseye_shows_all_types_and_no_loops_needed():
    sim = empty_road(make_sim())
    empty = birdseye_camera(sim)
    place(sim, 1, 10.0, 0, "CHV", color=(10, 240, 10))
    img = birdseye_camera(sim)
    assert img.shape == (2, 3, H, W) and img.dtype == torch.uint8
    green = (img[0, 1] == 240) & (img[0, 0] == 10)
    assert green.any() and not torch.equal(img, empty)


def test_camera_far_vehicle_beyond_max_range_not_drawn():
    sim = empty_road(make_sim())
    place(sim, 1, 100.0, 2, "CHV")
    assert vehicle_pixels(sim, max_range=150.0).any()
    assert not vehicle_pixels(sim, max_range=50.0).any()


# ----------------------------------------------------------------------------- coordinates
def test_coordinates_order_padding_and_connected_only():
    sim = empty_road(make_sim())
    place(sim, 1, 30.0, 0, "NCV", speed=10.0)
    place(sim, 2, -5.0, 4, "NCV", speed=20.0)
    place(sim, 3, 2.0, 1, "CHV")
    place(sim, 4, 50.0, 2, "NCV")  # out of range
    v = coordinates(sim, k=4).view(2, 4, 6)
    assert v.shape == (2, 4, 6)
    rows = v[0]
    assert rows[:, 0].tolist() == [1.0, 1.0, 0.0, 0.0]
    assert rows[0, 1].item() == pytest.approx(-5.0 / D_R)
    assert rows[1, 1].item() == pytest.approx(30.0 / D_R)
    road = sim.config.lanes * sim.config.lane_width
    assert rows[0, 2].item() == pytest.approx((float(sim.lane_centres[4]) - float(sim.lane_centres[2])) / road)
    mid = (sim.config.v_max + sim.config.v_min) / 2
    assert rows[0, 3].item() == pytest.approx((20.0 - mid) / mid)
    assert rows[0, 4].item() == pytest.approx(2.25) and rows[0, 5].item() == pytest.approx(0.9)
    assert (rows[2:] == 0).all()


def test_coordinates_k_larger_than_slots():
    sim = make_sim(n_envs=1)
    k = sim.state.n_vehicles + 5
    assert coordinates(sim, k=k).shape == (1, k * 6)


# ----------------------------------------------------------------------------- frame stack
def test_frame_stack_reset_leaves_no_old_frame():
    fs = FrameStack(3)
    f0 = torch.zeros(2, 3, 4, 4, dtype=torch.uint8)
    fs.reset(f0)
    for i in range(1, 5):
        out = fs.push(torch.full_like(f0, i))
    assert out[:, -3:].eq(4).all() and out[:, :3].eq(2).all()
    new = torch.full_like(f0, 9)
    out = fs.reset(new, torch.tensor([True, False]))
    assert out[0].eq(9).all(), "no frame of the previous episode survives a reset"
    assert out[1, :3].eq(2).all() and out[1, -3:].eq(4).all(), "other envs keep their stacks"
    out = fs.push(torch.full_like(f0, 10))
    assert out[0, :6].eq(9).all() and out[0, 6:].eq(10).all()


def test_frame_stack_flat_vectors():
    fs = FrameStack(2)
    out = fs.reset(torch.ones(3, 5))
    assert out.shape == (3, 10)
    out = fs.push(torch.full((3, 5), 2.0))
    assert out[:, :5].eq(1).all() and out[:, 5:].eq(2).all()


# ----------------------------------------------------------------------------- config and builder
@pytest.mark.parametrize("bad,match", [
    ({"camera": "fisheye"}, "fisheye"), ({"hgm": "fancy"}, "fancy"), ({"height": 35}, "36"),
    ({"width": 20}, "36"), ({"frame_stack": 0}, "frame_stack"), ({"v2x_range": -1.0}, "v2x_range"),
    ({"coord_k": 0}, "coord_k"), ({"camera_fov_deg": 180.0}, "camera_fov_deg"),
    ({"camera_pitch_deg": -5.0}, "camera_pitch_deg"), ({"camera_pitch_deg": 60.0}, "camera_pitch_deg"),
    ({"vehicle_height": 1.1, "camera_height": 1.2}, "vehicle_height"),
])
def test_config_rejects_bad_values(bad, match):
    with pytest.raises(ValueError, match=match):
        observation_config("proposed", **bad)


def test_config_needs_every_field_from_the_config_files():
    """No value has a second default in code: a node without a field is refused, naming it."""
    node = observation_node()
    del node["camera_height"]
    with pytest.raises(ValueError, match=r"misses field\(s\) \['camera_height'\]"):
        ObservationConfig.from_config(node, {"camera": "front", "hgm": "paper", "coordinates": False})
    with pytest.raises(ValueError, match=r"model.streams misses field\(s\) \['coordinates'\]"):
        ObservationConfig.from_config(observation_node(), {"camera": "front", "hgm": "paper"})
    # The defaults are conf/config.yaml's, so the camera sits where the config file says.
    from omegaconf import OmegaConf

    assert observation_config("proposed").camera_height == OmegaConf.load("conf/config.yaml").observation.camera_height


def test_config_from_nodes():
    from omegaconf import OmegaConf

    root = OmegaConf.load("conf/config.yaml")
    model = OmegaConf.load("conf/model/proposed.yaml")
    cfg = ObservationConfig.from_config(root.observation, model.streams)
    assert cfg.camera == "front" and cfg.hgm == "paper" and cfg.coordinates is False and cfg.height == 84
    assert cfg.keys == ("camera", "hgm")
    with pytest.raises(ValueError, match="unknown"):
        ObservationConfig.from_config({"heigth": 84}, {})


@pytest.mark.parametrize("streams", [
    {"camera": "front", "hgm": "paper", "coordinates": False},
    {"camera": "front", "hgm": "none", "coordinates": True},
    {"camera": "birdseye", "hgm": "enriched", "coordinates": False},
    {"camera": "none", "hgm": "none", "coordinates": False},
])
def test_builder_shapes_match_specs(streams):
    sim = make_sim(n_envs=3)
    cfg = observation_config(streams, frame_stack=2, coord_k=4)
    b = ObservationBuilder(sim, cfg)
    specs = b.specs()
    for obs in (b.reset(), b.step(), b.reset(torch.tensor([True, False, True]))):
        assert set(obs) == set(specs) == set(cfg.keys)
        for k, (shape, dtype) in specs.items():
            assert obs[k].shape == (3, *shape) and obs[k].dtype == dtype


def test_builder_reset_refills_only_masked_envs():
    sim = make_sim(n_envs=2)
    b = ObservationBuilder(sim, observation_config("proposed", camera="none", frame_stack=3))
    b.reset()
    for _ in range(3):
        sim.step(torch.full((2,), 4))
        before = b.step()["hgm"].clone()
    sim.reset(torch.tensor([True, False]))
    after = b.reset(torch.tensor([True, False]))["hgm"]
    frame = b.frame()["hgm"]
    assert torch.equal(after[0], frame[0].repeat(3, 1, 1))
    assert torch.equal(after[1], before[1])


def test_builder_partial_reset_draws_the_reset_envs_as_a_full_frame_would():
    sim = make_sim(n_envs=3, seed=5)
    cfg = observation_config("proposed", hgm="enriched", coordinates=True, frame_stack=3)
    b = ObservationBuilder(sim, cfg)
    b.reset()
    for _ in range(2):
        sim.step(torch.full((3,), 4))
        before = b.step()
    mask = torch.tensor([False, True, False])
    sim.reset(mask)
    held = {k: v.clone() for k, v in before.items()}
    after = b.reset(mask)
    full = b.frame()
    for k in after:
        assert torch.equal(before[k], held[k]), "a stack handed out earlier is never modified"
        assert torch.equal(after[k][1], full[k][1].repeat(3, *([1] * (full[k].dim() - 2))))
        assert torch.equal(after[k][mask.logical_not()], before[k][mask.logical_not()])


def test_camera_with_no_vehicle_in_view_is_background_only():
    sim = empty_road(make_sim())
    img = front_camera(sim)
    assert img.shape == (2, 3, H, W) and img.dtype == torch.uint8
    sky, road = img[0, :, 0, W // 2], img[0, :, H - 1, W // 2]
    assert sky[2] > sky[0] and abs(int(road[0]) - int(road[2])) < 10


def _first_road_row(img: torch.Tensor) -> int:
    """Index of the first row whose middle pixel is grey road rather than blue sky."""
    mid = img[0, :, :, img.shape[-1] // 2].int()  # [3, H]
    sky = mid[2] > mid[0] + 20
    return int((~sky).nonzero()[0])


@pytest.mark.parametrize("pitch", [10.0, 15.0, 25.0])
def test_camera_pitch_moves_the_horizon_up_by_f_tan_pitch(pitch):
    import math

    sim = empty_road(make_sim())
    level = _first_road_row(front_camera(sim, pitch_deg=0.0))
    pitched = _first_road_row(front_camera(sim, pitch_deg=pitch))
    f = (W / 2) / math.tan(math.radians(90.0) / 2)
    assert level == H // 2
    assert abs((level - pitched) - f * math.tan(math.radians(pitch))) <= 1.0


def test_pitched_camera_keeps_a_car_ahead_upright_and_taller_cars_reach_higher():
    sim = empty_road(make_sim())
    place(sim, 1, 15.0, 2, "CHV")
    low = vehicle_pixels(sim, pitch_deg=15.0, vehicle_height=1.5)[0]
    high = vehicle_pixels(sim, pitch_deg=15.0, vehicle_height=2.5)[0]
    cols_low, cols_high = low.any(0).nonzero().flatten(), high.any(0).nonzero().flatten()
    assert torch.equal(cols_low, cols_high)  # the same columns: the image plane stays vertical
    assert int(high.any(1).nonzero().min()) < int(low.any(1).nonzero().min())
    assert int(high.any(1).nonzero().max()) == int(low.any(1).nonzero().max())  # same wheels on the road


def test_camera_refuses_vehicles_lower_than_itself():
    sim = empty_road(make_sim())
    with pytest.raises(ValueError, match="vehicle_height"):
        front_camera(sim, camera_height=1.6, vehicle_height=1.5)
