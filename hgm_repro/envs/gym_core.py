"""What the single Gymnasium env and the VectorEnv share: one batched simulator, its observations,
the seeding rule, the next-step autoreset, and `info` in Gymnasium's vector convention.

Everything here is a batch of torch tensors ([N] or [N, ...] on the simulator's device); the envs
only convert at the edge (env 0 to Python scalars, or the batch to numpy). `info` maps `key` to
[N] values and `_key` to the [N] mask of the envs that report it, nested dicts alike, and holds a
key only when some env reports it: exactly what `gymnasium.vector.SyncVectorEnv` would build from
the single env's infos.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from ..contracts.config_files import scenario_config, simulator_config
from ..simulator.highway import HighwaySimulator, StepResult
from ..simulator.state import HOST
from .gym_observations import GymObservations, Observation

Info = dict[str, Any]


def _report(info: Info, values: Mapping[str, Any], mask: torch.Tensor) -> None:
    """Adds `values` (tensors [N], or dicts of them) for the envs in `mask` to `info`."""
    if not bool(mask.any()):
        return
    for key, value in values.items():
        if isinstance(value, Mapping):
            _report(info.setdefault(key, {}), value, mask)
        else:
            info[key] = torch.where(mask, value, torch.zeros_like(value))
        info[f"_{key}"] = mask


def env_info(info: Info, index: int) -> dict[str, Any]:
    """One env's info (Python scalars) out of a batched one: what a single env returns."""
    out: dict[str, Any] = {}
    for key, value in info.items():
        if key.startswith("_") or not bool(info[f"_{key}"][index]):
            continue
        out[key] = env_info(value, index) if isinstance(value, dict) else value[index].item()
    return out


def to_numpy(tree: Any) -> Any:
    """Tensors -> numpy arrays, through dicts (the VectorEnv's default output)."""
    if isinstance(tree, dict):
        return {k: to_numpy(v) for k, v in tree.items()}
    return tree.detach().cpu().numpy()


class GymHighway:
    """`n_envs` envs of the heterogeneous highway with the observation named `observation`.

    The simulator has one random generator for the whole batch; its seed is the constructor's
    `seed` until a reset passes one."""

    def __init__(self, n_envs: int, scenario: str | Mapping[str, Any] = "train",
                 simulator_overrides: Mapping[str, Any] | None = None, observation: str = "hgm",
                 observation_overrides: Mapping[str, Any] | None = None, seed: int | None = None,
                 kinematics_vehicles: int = 15, kinematics_range: float = 100.0,
                 device: torch.device | str = "cpu"):
        self.sim_config = simulator_config(**dict(simulator_overrides or {}))
        self.scenario = scenario_config(scenario, self.sim_config)
        self.sim = HighwaySimulator(self.sim_config, self.scenario, n_envs=n_envs, device=device,
                                    seed=0 if seed is None else seed)
        self.observations = GymObservations(self.sim, observation, observation_overrides, kinematics_vehicles,
                                            kinematics_range)
        self._everyone = torch.ones(n_envs, dtype=torch.bool, device=self.sim.device)
        self._seed = seed
        self._seeded = False

    def _state_info(self) -> dict[str, torch.Tensor]:
        s = self.sim.state
        return {"speed_kmh": s.speed[:, HOST].double() * 3.6, "lane": s.target_lane[:, HOST].long(),
                "decision": s.decision.long()}

    def reset(self, seed: int | None, np_random: np.random.Generator,
              mask: torch.Tensor | None = None) -> tuple[Observation, Info]:
        """New episodes in the envs of `mask` (all when None); observations of every env, info of those."""
        # The simulator's torch generator drives all traffic randomness: seeding it is what makes
        # the same seed replay the same episodes. Unseeded first resets use the constructor's seed,
        # or one drawn from Gymnasium's np_random (itself seeded from the OS).
        if seed is None and not self._seeded:
            seed = self._seed if self._seed is not None else int(np_random.integers(2**62))
        if seed is not None:
            self.sim.generator.manual_seed(int(seed))
            self._seeded = True
        self.sim.reset(mask)
        obs = self.observations.reset(mask)
        info: Info = {}
        _report(info, self._state_info(), self._everyone if mask is None else mask)
        return obs, info

    def step(self, actions: torch.Tensor, restart: torch.Tensor | None = None
             ) -> tuple[Observation, torch.Tensor, torch.Tensor, torch.Tensor, Info]:
        """One decision of every env; the envs in `restart` (their episode ended on the previous
        step: Gymnasium's next-step autoreset) start a new episode instead and report reward 0,
        not terminated, not truncated, and only the reset info."""
        result: StepResult = self.sim.step(actions)
        if restart is None:
            stepped = self._everyone
            obs = self.observations.step()
        else:
            # The batch steps as one, so the restarting envs were stepped too; the reset below
            # overwrites that step (all but the simulator-lifetime NPC health counters).
            stepped = ~restart
            self.sim.reset(restart)
            obs = self.observations.step(restart)
        reward = torch.where(stepped, result.reward, torch.zeros_like(result.reward))
        terminated, truncated = result.terminated & stepped, result.truncated & stepped
        info: Info = {}
        _report(info, self._state_info(), self._everyone)
        _report(info, {"reward_terms": {k: v.double() for k, v in result.terms.as_dict().items()},
                       "lane_change": result.lane_change.bool(), "overtakes": result.overtakes.long(),
                       "dangerous": result.dangerous.bool(), "collision": result.collision.bool()}, stepped)
        _report(info, {"episode_metrics": {k: v.double() for k, v in result.episode.items()}},
                terminated | truncated)
        return obs, reward, terminated, truncated, info
