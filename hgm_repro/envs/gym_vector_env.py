"""A batch of envs of the heterogeneous highway as one `gymnasium.vector.VectorEnv`.

    envs = gymnasium.make_vec("hgm_repro/HeterogeneousHighway-v0", num_envs=256,
                              vectorization_mode="vector_entry_point", observation="hgm")

One `HighwaySimulator` with n_envs=N and the same `ObservationBuilder` as the TorchRL env step
every env at once (no Python loop over envs), so Gymnasium-based learners get the batched speed.
It takes the single env's arguments and observations, batched: a Dict of uint8/float32 arrays
[N, ...] for "hgm", "camera", "coordinates", a float32 Box [N, K+1, 5] for "kinematics".
Autoreset is Gymnasium 1.x's default, next-step (`metadata["autoreset_mode"]`): the step after an
episode ends returns the new episode's first observation, reward 0, terminated and truncated
False. `info` follows the vector convention (`key` -> [N] array, `_key` -> which envs report it):
every step `speed_kmh`, `lane`, `decision`; for the envs that stepped `reward_terms`,
`lane_change`, `overtakes`, `dangerous`, `collision`; for the envs whose episode ended
`episode_metrics` (the paper's per-episode metrics). With `array_type="torch"`, observations,
rewards, flags and info are torch tensors on `device` instead of numpy arrays.

Returned arrays are views of the env's own buffers on CPU: copy one before changing it in place.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..simulator.state import N_ACTIONS
from .gym_core import GymHighway, Info, to_numpy
from .render import render_top_down

ARRAY_TYPES = ("numpy", "torch")


class HeterogeneousHighwayVectorEnv(VectorEnv):
    """`num_envs` envs of the paper's highway, stepped as one batch; see the module docstring."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, scenario: str | Mapping[str, Any] = "train",
                 simulator_overrides: Mapping[str, Any] | None = None, observation: str = "hgm",
                 observation_overrides: Mapping[str, Any] | None = None, render_mode: str | None = None,
                 seed: int | None = None, kinematics_vehicles: int = 15, kinematics_range: float = 100.0,
                 device: torch.device | str = "cpu", array_type: str = "numpy"):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode={render_mode!r} is not allowed; choose None or 'rgb_array'")
        if array_type not in ARRAY_TYPES:
            raise ValueError(f"array_type={array_type!r} is not allowed; choose one of {list(ARRAY_TYPES)}")
        self.core = GymHighway(num_envs, scenario, simulator_overrides, observation, observation_overrides, seed,
                               kinematics_vehicles, kinematics_range, device)
        self.sim = self.core.sim
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.array_type = array_type
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.core.sim_config.decision_dt)}
        self.single_observation_space = self.core.observations.single_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.single_action_space = gym.spaces.Discrete(N_ACTIONS)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._restart: torch.Tensor | None = None  # envs whose episode ended on the last step
        self._last_actions: torch.Tensor | None = None

    def _out(self, tree: Any) -> Any:
        return to_numpy(tree) if self.array_type == "numpy" else tree

    def _actions(self, actions: Any) -> torch.Tensor:
        a = torch.as_tensor(np.asarray(actions) if not isinstance(actions, torch.Tensor) else actions,
                            device=self.sim.device)
        if a.shape != (self.num_envs,) or a.dtype.is_floating_point or a.dtype == torch.bool:
            raise ValueError(f"actions must be {self.num_envs} integers in [0, {N_ACTIONS}), got {a.dtype} "
                             f"{tuple(a.shape)}")
        if bool(((a < 0) | (a >= N_ACTIONS)).any()):
            raise ValueError(f"actions must be integers in [0, {N_ACTIONS}), got {actions!r}")
        return a.long()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, Info]:
        """All envs, or with `options={"reset_mask": bool array [N]}` only those (the others keep
        their episodes). `seed` must be one int: the batch shares one random generator."""
        if seed is not None and not isinstance(seed, int | np.integer):
            raise ValueError(f"seed={seed!r}: pass one int (or None); the batched simulator has one random "
                             "generator for all its envs, so per-env seeds cannot be honoured")
        super().reset(seed=seed)
        mask = None
        if options is not None and "reset_mask" in options:
            given = np.asarray(options["reset_mask"])
            if given.shape != (self.num_envs,) or given.dtype != np.bool_ or not given.any():
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({self.num_envs},) with at "
                                 f"least one True, got {given!r}")
            mask = torch.as_tensor(given, device=self.sim.device)
        obs, info = self.core.reset(seed, self.np_random, mask)
        if mask is None or self._restart is None:
            self._restart = None
        else:
            self._restart = self._restart & ~mask
            if not bool(self._restart.any()):
                self._restart = None
        self._last_actions = None
        return self._out(obs), self._out(info)

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, Info]:
        self._last_actions = self._actions(actions)
        obs, reward, terminated, truncated, info = self.core.step(self._last_actions, self._restart)
        done = terminated | truncated
        self._restart = done if bool(done.any()) else None
        if self.array_type == "numpy":
            # float64 rewards, as gymnasium.vector.SyncVectorEnv returns them
            return (to_numpy(obs), reward.double().cpu().numpy(), terminated.cpu().numpy(),
                    truncated.cpu().numpy(), to_numpy(info))
        return obs, reward, terminated, truncated, info

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One top-down picture per env (drawn one by one with PIL: for watching, not for speed)."""
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        actions = [None] * self.num_envs if self._last_actions is None else self._last_actions.tolist()
        return tuple(render_top_down(self.sim, i, action=actions[i]) for i in range(self.num_envs))
