"""One env of the heterogeneous highway behind the Gymnasium API.

The batched TorchRL env is the fast path for training; this wrapper is for people and tools that
speak Gymnasium (`gymnasium.make("hgm_repro/HeterogeneousHighway-v0")`): one simulator with
n_envs=1, numpy observations, Python scalars for rewards and flags.

Observations, chosen by name:
- "hgm", "camera", "coordinates": what the proposed method, Min's method and the Coordinate
  method see (the streams of conf/model/{proposed,min,coordinate}.yaml), built by
  `hgm_repro.observations.ObservationBuilder`, as a Dict space keyed like the TorchRL env;
- "kinematics": a small Box of the host and its nearest vehicles (ground truth, every vehicle,
  connected or not: a debugging and smoke-test view, not one of the paper's sensors). It needs no
  observation package, so the env works on its own.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import yaml

from .. import CONF_DIR
from ..simulator.config import ScenarioConfig, SimulatorConfig
from ..simulator.highway import HighwaySimulator
from ..simulator.loading import load_yaml, scenario_config, simulator_config
from ..simulator.state import HOST, N_ACTIONS, Action
from .render import render_top_down

ENV_ID = "hgm_repro/HeterogeneousHighway-v0"
OBSERVATIONS = ("hgm", "camera", "coordinates", "kinematics")
# Which model's streams each observation name stands for.
_STREAMS_OF = {"hgm": "proposed", "camera": "min", "coordinates": "coordinate"}
KINEMATICS_FEATURES = ("present", "rel_lon", "rel_lat", "rel_speed", "lane")


def register_envs() -> None:
    """Register the env with Gymnasium; calling it again does nothing."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="hgm_repro.envs.gym_env:HeterogeneousHighwayGymEnv")


def _default_observation_params() -> dict[str, Any]:
    # The root config's `observation` node (plain YAML; Hydra is not needed to read it).
    return dict(yaml.safe_load((CONF_DIR / "config.yaml").read_text())["observation"])


class HeterogeneousHighwayGymEnv(gym.Env):
    """The paper's five-lane highway with heterogeneous traffic; the agent drives the host.

    Actions: Discrete(5) in `Action` order (accelerate, decelerate, lane left, lane right, no
    action), one per decision (0.5 s by default). An episode ends with a host collision
    (terminated) or when its driving time is up (truncated)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, scenario: str | Mapping[str, Any] = "train",
                 simulator_overrides: Mapping[str, Any] | None = None, observation: str = "hgm",
                 observation_overrides: Mapping[str, Any] | None = None, render_mode: str | None = None,
                 seed: int | None = None, kinematics_vehicles: int = 15, kinematics_range: float = 100.0):
        if observation not in OBSERVATIONS:
            raise ValueError(f"observation={observation!r} is not allowed; choose one of {list(OBSERVATIONS)}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode={render_mode!r} is not allowed; choose None or 'rgb_array'")
        self.render_mode = render_mode
        self.observation = observation
        self.sim_config: SimulatorConfig = simulator_config(**dict(simulator_overrides or {}))
        self.scenario: ScenarioConfig = scenario_config(scenario, self.sim_config)
        self._seed = seed
        self._seeded = False
        self.sim = HighwaySimulator(self.sim_config, self.scenario, n_envs=1, seed=0 if seed is None else seed)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.sim_config.decision_dt)}
        self.action_space = gym.spaces.Discrete(N_ACTIONS)
        self._last_action: int | None = None
        self._k = int(kinematics_vehicles)
        self._range = float(kinematics_range)
        self._builder = None
        if observation == "kinematics":
            self.observation_space = gym.spaces.Box(-1.0, 1.0, (self._k + 1, len(KINEMATICS_FEATURES)), np.float32)
        else:
            self._builder = self._make_builder(observation, observation_overrides)
            probe = self._to_numpy(self._builder.reset(torch.ones(1, dtype=torch.bool)))
            self.observation_space = gym.spaces.Dict({k: self._box_for(v) for k, v in probe.items()})

    # ----------------------------------------------------------------------------- observations
    def _make_builder(self, observation: str, overrides: Mapping[str, Any] | None) -> Any:
        from ..observations import ObservationBuilder, ObservationConfig

        params = {**_default_observation_params(), **dict(overrides or {})}
        streams = load_yaml("model", _STREAMS_OF[observation])["streams"]
        return ObservationBuilder(self.sim, ObservationConfig.from_config(params, streams))

    @staticmethod
    def _box_for(value: np.ndarray) -> gym.spaces.Box:
        if value.dtype == np.uint8:
            return gym.spaces.Box(0, 255, value.shape, np.uint8)
        return gym.spaces.Box(-np.inf, np.inf, value.shape, value.dtype.type)

    @staticmethod
    def _to_numpy(obs: Mapping[str, torch.Tensor]) -> dict[str, np.ndarray]:
        return {k: v[0].detach().cpu().numpy() for k, v in obs.items()}

    def _kinematics(self) -> np.ndarray:
        """Host row (absolute: lateral position, speed, lane, each in [0, 1]), then the K nearest
        active vehicles along the road within `kinematics_range`, relative to the host, nearest first."""
        s, c = self.sim.state, self.sim_config
        road_w = c.lanes * c.lane_width
        lane_span = max(c.lanes - 1, 1)
        dx = s.pos_lon[0] - s.pos_lon[0, HOST]
        visible = s.active[0] & (dx.abs() < self._range)
        visible[HOST] = False
        dist = torch.where(visible, dx.abs(), torch.inf)
        k = min(self._k, dist.numel())
        near = torch.topk(dist, k, largest=False).indices
        rows = torch.stack([
            visible[near].float(),
            dx[near] / self._range,
            (s.pos_lat[0, near] - s.pos_lat[0, HOST]) / road_w,
            (s.speed[0, near] - s.speed[0, HOST]) / c.v_max,
            (s.target_lane[0, near] - s.target_lane[0, HOST]).float() / lane_span,
        ], dim=1) * visible[near].float().unsqueeze(1)
        host = torch.tensor([1.0, 0.0, float(s.pos_lat[0, HOST]) / road_w, float(s.speed[0, HOST]) / c.v_max,
                             float(s.target_lane[0, HOST]) / lane_span])
        out = torch.zeros(self._k + 1, len(KINEMATICS_FEATURES))
        out[0] = host
        out[1:k + 1] = rows
        return out.clamp(-1.0, 1.0).numpy().astype(np.float32)

    def _observe(self, reset: bool) -> np.ndarray | dict[str, np.ndarray]:
        if self._builder is None:
            return self._kinematics()
        obs = self._builder.reset(torch.ones(1, dtype=torch.bool)) if reset else self._builder.step()
        return self._to_numpy(obs)

    # ----------------------------------------------------------------------------- gymnasium api
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray | dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        # The simulator's torch generator drives all traffic randomness: seeding it is what makes
        # the same seed replay the same episode. Unseeded first resets use the constructor's seed,
        # or one drawn from Gymnasium's np_random (itself seeded from the OS).
        if seed is None and not self._seeded:
            seed = self._seed if self._seed is not None else int(self.np_random.integers(2**62))
        if seed is not None:
            self.sim.generator.manual_seed(int(seed))
            self._seeded = True
        self.sim.reset()
        self._last_action = None
        return self._observe(reset=True), self._info()

    def step(self, action: int | np.integer) -> tuple[np.ndarray | dict[str, np.ndarray], float, bool, bool,
                                                      dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"action={action!r} is not in {self.action_space}")
        self._last_action = int(action)
        result = self.sim.step(torch.tensor([self._last_action], device=self.sim.device))
        terminated, truncated = bool(result.terminated[0]), bool(result.truncated[0])
        info = self._info()
        info.update(
            reward_terms={k: float(v[0]) for k, v in result.terms.as_dict().items()},
            lane_change=bool(result.lane_change[0]), overtakes=int(result.overtakes[0]),
            dangerous=bool(result.dangerous[0]), collision=bool(result.collision[0]),
        )
        if terminated or truncated:
            info["episode_metrics"] = {k: float(v[0]) for k, v in result.episode.items()}
        return self._observe(reset=False), float(result.reward[0]), terminated, truncated, info

    def _info(self) -> dict[str, Any]:
        s = self.sim.state
        return {"speed_kmh": float(s.speed[0, HOST]) * 3.6, "lane": int(s.target_lane[0, HOST]),
                "decision": int(s.decision[0])}

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        return render_top_down(self.sim, 0, action=self._last_action)

    def action_meanings(self) -> list[str]:
        return [a.name.lower() for a in Action]
