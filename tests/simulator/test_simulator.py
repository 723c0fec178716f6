"""The simulator against the paper's tables (Table 1, Table 2, Table 5, eqs. 2-3, Algorithm 2)."""

from __future__ import annotations

import math

import pytest
import torch
from scipy import stats

from hgm_repro.contracts.conf_dir import load_yaml
from hgm_repro.contracts.config_files import scenario_config, simulator_config
from hgm_repro.simulator import HOST, Action, ConfigError
from tests.helpers.sim import calm, empty_road, make_sim, place

KMH = 1 / 3.6


def step(sim, action: Action):
    return sim.step(torch.full((sim.n_envs,), int(action)))


# ----------------------------------------------------------------------------- eq. 2 and eq. 3
def test_acceleration_gains_a_lon_per_second_until_v_max():
    sim = empty_road(make_sim(), host_speed=40 * KMH)
    a_lon = sim.config.vehicle_types[0].a_lon
    v0 = float(sim.state.speed[0, HOST])
    for k in range(1, 20):
        step(sim, Action.ACCELERATE)
        expected = min(v0 + a_lon * sim.config.decision_dt * k, sim.config.v_max)
        assert float(sim.state.speed[0, HOST]) == pytest.approx(expected, abs=1e-4)
    assert float(sim.state.speed[0, HOST]) == pytest.approx(sim.config.v_max)
    step(sim, Action.ACCELERATE)  # at v_max the acceleration is 0
    assert float(sim.state.speed[0, HOST]) == pytest.approx(sim.config.v_max)


def test_deceleration_stops_at_v_min():
    sim = empty_road(make_sim(), host_speed=45 * KMH)
    for _ in range(10):
        step(sim, Action.DECELERATE)
    assert float(sim.state.speed[0, HOST]) == pytest.approx(sim.config.v_min)


@pytest.mark.parametrize("type_name, v_lat", [("CHV", 1.0), ("AHV", 2.0)])
def test_lane_change_takes_lane_width_over_v_lat(type_name, v_lat):
    sim = empty_road(make_sim(physics_dt=0.05))
    sim.state.vtype[0, HOST] = sim.config.type_index(type_name)
    w = sim.config.lane_width
    start = float(sim.state.pos_lat[0, HOST])
    step(sim, Action.LANE_LEFT)
    t = sim.config.decision_dt
    moved = [start - float(sim.state.pos_lat[0, HOST])]
    while moved[-1] < w - 1e-6 and t < 10:
        step(sim, Action.NO_ACTION)
        t += sim.config.decision_dt
        moved.append(start - float(sim.state.pos_lat[0, HOST]))
    # The lateral displacement grows by v_lat per second until the next lane's centre is reached.
    for k, d in enumerate(moved, start=1):
        assert d == pytest.approx(min(v_lat * sim.config.decision_dt * k, w), abs=1e-4)
    assert t == pytest.approx(math.ceil(w / v_lat / sim.config.decision_dt) * sim.config.decision_dt)


def test_no_new_lane_change_while_one_is_under_way():
    sim = empty_road(make_sim())
    step(sim, Action.LANE_LEFT)
    res = step(sim, Action.LANE_LEFT)  # ignored: the first change is still under way
    assert not bool(res.lane_change[0])
    assert int(sim.state.target_lane[0, HOST]) == 1


def test_lane_change_off_the_road_is_dangerous_and_not_executed():
    sim = empty_road(make_sim(), host_lane=0)
    res = step(sim, Action.LANE_LEFT)
    assert int(sim.state.target_lane[0, HOST]) == 0
    assert bool(res.dangerous[0]) and not bool(res.lane_change[0])
    assert float(res.terms.dangerous[0]) == sim.config.reward.dangerous


# ----------------------------------------------------------------------------- Table 2 rewards
@pytest.mark.parametrize("kmh, expected", [(40, 0.0), (60, 1.25), (80, 3.0)])
def test_speed_term(kmh, expected):
    sim = empty_road(make_sim(), host_speed=kmh * KMH)
    res = step(sim, Action.NO_ACTION)
    assert float(res.terms.speed[0]) == pytest.approx(expected, abs=1e-5)
    assert float(res.reward[0]) == pytest.approx(expected, abs=1e-5)


def test_collision_reward_and_termination():
    sim = calm(empty_road(make_sim(), host_speed=80 * KMH))
    place(sim, 1, lon=6.0, lane=2, speed=40 * KMH)  # 1.5 m bumper gap, closing at 11 m/s
    res = step(sim, Action.NO_ACTION)
    assert bool(res.collision[0]) and bool(res.terminated[0]) and not bool(res.truncated[0])
    assert float(res.terms.collision[0]) == -20.0
    assert float(res.episode["collisions"][0]) == 1.0


@pytest.mark.parametrize("bumper_gap, crash_decision", [(9.5, 1), (10.5, 2)])
def test_rear_end_is_charged_on_the_decision_it_happens_in(bumper_gap, crash_decision):
    # Closing at 20 m/s, the host gains 2 m per 0.1 s sub-step and 10 m per decision: a 9.5 m gap
    # closes in the decision's last sub-step and must be charged to it, a 10.5 m gap in the next one.
    sim = calm(empty_road(make_sim(), host_speed=30.0))
    half_lengths = float(sim.half_len_by_type[0] + sim.half_len_by_type[sim.config.type_index("CHV")])
    place(sim, 1, lon=half_lengths + bumper_gap, lane=2, speed=10.0)
    for decision in range(1, 3):
        res = step(sim, Action.NO_ACTION)
        assert bool(res.collision[0]) == (decision == crash_decision), decision
        if bool(res.collision[0]):
            break


def test_a_crash_never_pays_an_overtake():
    # The host passes a slow car in the next lane and runs into another in its own lane within one
    # decision: the collision ends the decision, so neither counts as overtaken.
    sim = calm(empty_road(make_sim(), host_speed=30.0))
    place(sim, 1, lon=2.0, lane=1, speed=10.0)
    half_lengths = float(sim.half_len_by_type[0] + sim.half_len_by_type[sim.config.type_index("CHV")])
    place(sim, 2, lon=half_lengths + 4.0, lane=2, speed=10.0)
    res = step(sim, Action.NO_ACTION)
    assert bool(res.collision[0])
    assert float(res.overtakes[0]) == 0 and float(res.terms.overtake[0]) == 0.0
    assert float(res.reward[0]) == pytest.approx(float(res.terms.speed[0] + res.terms.collision[0]
                                                       + res.terms.dangerous[0]), abs=1e-5)


def test_always_accelerating_host_crashes_without_overtake_reward():
    # The reviewer's probe: a host that always accelerates in scenario 3 crashes often, and before the
    # fix about 45% of its crash steps were paid R_o (the host passed through the car it hit).
    sim = make_sim(n_envs=64, scenario="3", seed=0)
    crashes = paid = 0
    for _ in range(60):
        res = step(sim, Action.ACCELERATE)
        crashes += int(res.collision.sum())
        paid += int((res.collision & ((res.overtakes > 0) | (res.terms.overtake != 0))).sum())
        if bool(res.done.any()):
            sim.reset(res.done)
    assert crashes >= 50
    assert paid == 0


def test_dangerous_action_reward_when_tailgating():
    sim = calm(empty_road(make_sim(), host_speed=60 * KMH))
    place(sim, 1, lon=15.0, lane=2, speed=60 * KMH)  # 10.5 m at 16.7 m/s: 0.63 s time gap
    res = step(sim, Action.NO_ACTION)
    assert bool(res.dangerous[0]) and not bool(res.collision[0])
    assert float(res.terms.dangerous[0]) == -2.0


def test_lane_change_reward():
    sim = empty_road(make_sim())
    res = step(sim, Action.LANE_RIGHT)
    assert bool(res.lane_change[0])
    assert float(res.terms.lane_change[0]) == -1.0
    assert float(res.reward[0]) == pytest.approx(1.25 - 1.0, abs=1e-5)


def test_overtake_reward_counts_once_per_vehicle():
    sim = calm(empty_road(make_sim(), host_speed=80 * KMH))
    place(sim, 1, lon=3.0, lane=1, speed=40 * KMH)  # slow car in the next lane, just ahead
    res = step(sim, Action.NO_ACTION)
    assert float(res.overtakes[0]) == 1 and float(res.terms.overtake[0]) == 5.0
    # It passes the host back, and the host passes it again: no second reward.
    s = sim.state
    s.pos_lon[0, 1] = s.pos_lon[0, HOST] + 3.0
    s.speed[0, 1] = 80 * KMH
    s.speed[0, HOST] = 40 * KMH
    res = step(sim, Action.NO_ACTION)
    assert float(res.overtakes[0]) == 0
    s.pos_lon[0, 1] = s.pos_lon[0, HOST] + 3.0
    s.speed[0, 1] = 40 * KMH
    s.speed[0, HOST] = 80 * KMH
    res = step(sim, Action.NO_ACTION)
    assert float(res.overtakes[0]) == 0 and float(res.terms.overtake[0]) == 0.0
    assert float(res.episode["overtakes"][0]) == 1


def test_reward_is_the_sum_of_its_terms():
    sim = make_sim(n_envs=32, seed=3)
    gen = torch.Generator().manual_seed(0)
    for _ in range(40):
        res = sim.step(torch.randint(0, 5, (32,), generator=gen))
        total = sum(res.terms.as_dict().values())
        assert torch.allclose(res.reward, total)
        sim.reset(res.done)


# ----------------------------------------------------------------------------- traffic
def _spawned_types(scenario: str, n_envs=64, decisions=200, seed=0):
    sim = make_sim(n_envs=n_envs, scenario=scenario, seed=seed, host_safety_layer=True)
    seen = [sim.state.vtype[:, 1:].reshape(-1)]
    for _ in range(decisions):
        before = sim.state.vtype.clone(), sim.state.active.clone()
        res = sim.step(sim.npc_actions(sim.state)[:, HOST])
        respawned = (sim.state.active & ~before[1])[:, 1:]
        seen.append(sim.state.vtype[:, 1:][respawned])
        sim.reset(res.done)
    return sim, torch.cat(seen)


def test_spawned_types_match_the_scenario_ratios():
    sim, types = _spawned_types("2")
    names = sim.config.type_names
    counts = torch.bincount(types, minlength=len(names))
    assert counts[0] == 0  # nothing spawns as a host
    expected_share = torch.tensor([sim.scenario.ratio_of(n) for n in names])
    mask = expected_share > 0
    chi2 = stats.chisquare(counts[mask].numpy(), (expected_share[mask] * counts.sum()).numpy())
    assert chi2.pvalue > 0.001, (counts, expected_share)
    assert counts.sum() > 4000


def test_scenario_1_has_no_ncv_and_scenario_5_only_ncv():
    sim, types = _spawned_types("1", n_envs=16, decisions=100)
    assert not bool((types == sim.config.type_index("NCV")).any())
    sim, types = _spawned_types("5", n_envs=16, decisions=100)
    assert not bool((types == sim.config.type_index("CHV")).any())
    assert not bool((types == sim.config.type_index("AHV")).any())


def _trajectory(seed: int, device: str = "cpu"):
    cfg = simulator_config()
    from hgm_repro.simulator import HighwaySimulator

    sim = HighwaySimulator(cfg, scenario_config("train", cfg), 8, device=device, seed=seed)
    gen = torch.Generator().manual_seed(seed)
    out = []
    for _ in range(60):
        res = sim.step(torch.randint(0, 5, (8,), generator=gen).to(device))
        out.append(torch.stack([sim.state.pos_lon, sim.state.pos_lat, sim.state.speed]).cpu())
        out.append(res.reward.cpu().unsqueeze(0).expand(8, -1))
        sim.reset(res.done)
    return out


def test_same_seed_same_trajectory():
    a, b, c = _trajectory(7), _trajectory(7), _trajectory(8)
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(torch.equal(x, y) for x, y in zip(a, c, strict=True))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cpu_and_cuda_agree():
    cfg = simulator_config()
    from hgm_repro.simulator import HighwaySimulator

    cpu = HighwaySimulator(cfg, scenario_config("train", cfg), 8, device="cpu", seed=1)
    gpu = HighwaySimulator(cfg, scenario_config("train", cfg), 8, device="cuda", seed=1)
    gpu.state = cpu.state.to("cuda")
    # Random draws differ between devices: feed both the same NPC actions.
    for _ in range(30):
        acts = cpu.npc_actions(cpu.state)
        cpu.npc_actions = lambda state, a=acts: a.clone()
        gpu.npc_actions = lambda state, a=acts: a.cuda()
        cpu.respawn = gpu.respawn = False
        r1, r2 = cpu.step(acts[:, HOST]), gpu.step(acts[:, HOST].cuda())
        assert torch.allclose(r1.reward, r2.reward.cpu(), atol=1e-4)
        assert torch.allclose(cpu.state.pos_lon, gpu.state.pos_lon.cpu(), atol=1e-3)


def test_human_driven_host_keeps_npc_collisions_rare_and_vehicles_on_the_road():
    """10,000 decisions at default density, the host driven by the CHV model."""
    sim = make_sim(n_envs=50, seed=11, host_safety_layer=True)
    sim.state.vtype[:, HOST] = sim.config.type_index("CHV")  # drive the host with the CHV's rates too
    w_road = sim.config.lanes * sim.config.lane_width
    for _ in range(200):
        active_before = sim.state.active.clone()
        res = sim.step(sim.npc_actions(sim.state)[:, HOST])
        s = sim.state
        hw = sim.half_wid_by_type[s.vtype]
        on_road = (s.pos_lat - hw >= -1e-4) & (s.pos_lat + hw <= w_road + 1e-4)
        assert bool(on_road[s.active].all())
        # Newly spawned vehicles never overlap anyone.
        new = s.active & ~active_before
        if bool(new.any()):
            dlon = (s.pos_lon.unsqueeze(2) - s.pos_lon.unsqueeze(1)).abs()
            dlat = (s.pos_lat.unsqueeze(2) - s.pos_lat.unsqueeze(1)).abs()
            hl = sim.half_len_by_type[s.vtype]
            touch = (dlon < hl.unsqueeze(2) + hl.unsqueeze(1)) & (dlat < hw.unsqueeze(2) + hw.unsqueeze(1))
            touch &= s.active.unsqueeze(2) & s.active.unsqueeze(1)
            touch &= ~torch.eye(s.n_vehicles, dtype=torch.bool)
            assert not bool((touch & new.unsqueeze(2)).any())
        sim.reset(res.done)
    vehicle_km = float(sim.state.npc_distance.sum()) / 1000
    crashes = float(sim.state.npc_collisions.sum())
    assert vehicle_km > 2_000
    print(f"NPC-NPC crashes: {crashes:g} over {vehicle_km:.0f} vehicle-km, 10,000 decisions")
    assert crashes / vehicle_km * 1000 < 1.0, f"{crashes} NPC-NPC crashes over {vehicle_km:.0f} vehicle-km"


def test_density_stays_constant():
    sim = make_sim(n_envs=16, seed=2, host_safety_layer=True)
    counts = []
    for _ in range(200):
        res = sim.step(sim.npc_actions(sim.state)[:, HOST])
        counts.append(sim.state.active.float().mean())
        sim.reset(res.done)
    assert min(counts[50:]) > 0.88


def test_episode_truncates_after_episode_time():
    sim = make_sim(n_envs=2, episode_seconds=5.0)
    sim.host_safety_layer = True
    results = [sim.step(torch.full((2,), int(Action.NO_ACTION))) for _ in range(10)]
    assert not any(bool(r.done.any()) for r in results[:-1])
    res = results[-1]
    assert bool(res.done.all())
    assert torch.equal(res.truncated, ~res.terminated)
    assert torch.allclose(res.episode["decisions"], torch.tensor([10.0, 10.0]))


# ----------------------------------------------------------------------------- bad configs
@pytest.mark.parametrize("overrides, words", [
    (dict(lanes=0), ["simulator.lanes=0", ">= 1"]),
    (dict(v_min_kmh=80.0, v_max_kmh=80.0), ["v_min_kmh=80", "v_min < v_max"]),
    (dict(v_min_kmh=90.0), ["v_min_kmh=90", "v_max"]),
    (dict(physics_dt=0.3), ["decision_dt", "multiple"]),
    (dict(vehicle_types={"HV": dict(a_lon=2, v_lat=1, r_lon=-0.1, r_lat=0, connected=True, length=4.5, width=1.8,
                                    lane_change_time_gap=1.0)}),
     ["r_lon=-0.1", "[0, 1]"]),
    (dict(vehicle_types={"CHV": dict(a_lon=2, v_lat=1, r_lon=0, r_lat=0, connected=False)}), ["'HV'"]),
    # No value has a second default in code: a node without a field is refused, naming it.
    (dict(vehicle_types={"HV": dict(a_lon=2, v_lat=1, r_lon=0, r_lat=0, connected=True)}),
     ["vehicle_types.HV misses", "lane_change_time_gap", "length", "width"]),
    (dict(reward={"collision": -20.0}), ["simulator.reward misses", "overtake"]),
    (dict(bogus=1), ["bogus", "allowed"]),
])
def test_bad_simulator_config_names_the_value(overrides, words):
    with pytest.raises(ConfigError) as err:
        simulator_config(**overrides)
    for w in words:
        assert w in str(err.value)


def test_simulator_node_without_a_field_is_refused():
    """The YAML is the one place of each simulator value: a node that leaves one out is refused."""
    raw = load_yaml("simulator", "highway")
    del raw["lane_width"]
    with pytest.raises(ConfigError, match=r"simulator misses field\(s\) \['lane_width'\]"):
        simulator_config(raw)


@pytest.mark.parametrize("ratios, words", [
    ({"NCV": 0.5, "AHV": 0.25, "CHV": 0.3}, ["sum to 1.05", "must sum to 1"]),
    ({"NCV": 1.2, "AHV": -0.2}, ["ratios.AHV=-0.2", ">= 0"]),
    ({"NCV": 0.5, "TRUCK": 0.5}, ["unknown vehicle type 'TRUCK'", "NCV"]),
    ({"HV": 1.0}, ["unknown vehicle type 'HV'"]),
])
def test_bad_scenario_names_the_value(ratios, words):
    cfg = simulator_config()
    with pytest.raises(ConfigError) as err:
        scenario_config({"name": "x", "ratios": ratios}, cfg)
    for w in words:
        assert w in str(err.value)


def test_unknown_scenario_name_lists_the_allowed_ones():
    with pytest.raises(ConfigError, match=r"unknown scenario '7'.*'1', '2', '3', '4', '5', 'train'"):
        scenario_config("7", simulator_config())


def test_bad_n_envs():
    with pytest.raises(ValueError, match="n_envs=0"):
        make_sim(n_envs=0)


def test_npc_crash_is_counted_once_and_both_vehicles_leave():
    sim = calm(empty_road(make_sim(), host_speed=60 * KMH))
    place(sim, 1, lon=50.0, lane=0, speed=80 * KMH)
    place(sim, 2, lon=55.0, lane=0, speed=40 * KMH)  # 0.5 m bumper gap, closing at 11 m/s
    res = step(sim, Action.NO_ACTION)
    assert float(sim.state.npc_collisions[0]) == 1.0
    assert not bool(res.collision[0])  # the host was not involved
    assert not bool(sim.state.active[0, 1]) and not bool(sim.state.active[0, 2])
