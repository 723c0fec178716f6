"""Build simulators and hand-placed traffic situations for tests."""

from __future__ import annotations

import torch

from hgm_repro.contracts.config_files import scenario_config, simulator_config
from hgm_repro.simulator import HOST, HighwaySimulator


def make_sim(n_envs: int = 1, scenario: str = "train", seed: int = 0, **overrides) -> HighwaySimulator:
    cfg = simulator_config(**overrides)
    return HighwaySimulator(cfg, scenario_config(scenario, cfg), n_envs, seed=seed)


def empty_road(sim: HighwaySimulator, host_lane: int = 2, host_speed: float | None = None) -> HighwaySimulator:
    """Only the host on the road, and nobody respawning: a blank page for scripted situations."""
    s = sim.state
    s.active[:] = False
    s.active[:, HOST] = True
    s.pos_lon[:, HOST] = 0.0
    s.target_lane[:, HOST] = host_lane
    s.pos_lat[:, HOST] = sim.lane_centres[host_lane]
    if host_speed is not None:
        s.speed[:, HOST] = host_speed
    s.was_ahead[:] = False
    s.passed[:] = False
    sim.respawn = False
    return sim


def place(sim: HighwaySimulator, slot: int, lon: float, lane: int, speed: float, type_name: str = "CHV",
          env: int = 0) -> None:
    """Put vehicle `slot` of env `env` at `lon` metres in `lane`, driving at `speed` m/s."""
    s = sim.state
    s.active[env, slot] = True
    s.pos_lon[env, slot] = lon
    s.target_lane[env, slot] = lane
    s.pos_lat[env, slot] = sim.lane_centres[lane]
    s.speed[env, slot] = speed
    s.vtype[env, slot] = sim.config.type_index(type_name)
    s.was_ahead[env, slot] = lon > float(s.pos_lon[env, HOST])
    s.passed[env, slot] = False


def calm(sim: HighwaySimulator) -> HighwaySimulator:
    """Other vehicles take no random actions (r_lon = r_lat = 0), so scripts are deterministic."""
    sim.r_lon_by_type = torch.zeros_like(sim.r_lon_by_type)
    sim.r_lat_by_type = torch.zeros_like(sim.r_lat_by_type)
    return sim
