"""One env of the heterogeneous highway behind the Gymnasium API.

The batched TorchRL env is the fast path for training, and `gym_vector_env` gives Gymnasium users
the batch; this one is for people and tools that want a single env
(`gymnasium.make("hgm_repro/HeterogeneousHighway-v0")`): the shared `GymHighway` with n_envs=1,
numpy observations, Python scalars for rewards, flags and info. Observations are chosen by name
(see `gym_observations`: "hgm", "camera", "coordinates", "kinematics").
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from ..simulator.state import N_ACTIONS, Action
from .gym_core import GymHighway, env_info
from .gym_observations import Observation
from .render import render_top_down


def _first_env(obs: Observation) -> np.ndarray | dict[str, np.ndarray]:
    if isinstance(obs, dict):
        return {k: v[0].detach().cpu().numpy() for k, v in obs.items()}
    return obs[0].detach().cpu().numpy()


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
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode={render_mode!r} is not allowed; choose None or 'rgb_array'")
        self.render_mode = render_mode
        self.observation = observation
        self.core = GymHighway(1, scenario, simulator_overrides, observation, observation_overrides, seed,
                               kinematics_vehicles, kinematics_range)
        self.sim = self.core.sim
        self.sim_config = self.core.sim_config
        self.scenario = self.core.scenario
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.sim_config.decision_dt)}
        self.action_space = gym.spaces.Discrete(N_ACTIONS)
        self.observation_space = self.core.observations.single_space
        self._last_action: int | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray | dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        obs, info = self.core.reset(seed, self.np_random)
        self._last_action = None
        return _first_env(obs), env_info(info, 0)

    def step(self, action: int | np.integer) -> tuple[np.ndarray | dict[str, np.ndarray], float, bool, bool,
                                                      dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"action={action!r} is not in {self.action_space}")
        self._last_action = int(action)
        obs, reward, terminated, truncated, info = self.core.step(
            torch.tensor([self._last_action], device=self.sim.device))
        return _first_env(obs), float(reward[0]), bool(terminated[0]), bool(truncated[0]), env_info(info, 0)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        return render_top_down(self.sim, 0, action=self._last_action)

    def action_meanings(self) -> list[str]:
        return [a.name.lower() for a in Action]
