"""Environments over the batched simulator: TorchRL (the fast path) and Gymnasium (one env, or a
batch of them as a `gymnasium.vector.VectorEnv`).

Importing this package stays cheap (no torch): `import hgm_repro` registers the Gymnasium env
through it, and the env classes load on first use.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from .registration import ENV_ID, register_envs

_LAZY = {"HeterogeneousHighwayGymEnv": ".gym_env", "HeterogeneousHighwayVectorEnv": ".gym_vector_env",
         "HeterogeneousHighwayEnv": ".torchrl_env"}


def make_env(cfg: Any, scenario_node: Any, n_envs: int, seed: int) -> Any:
    """The TorchRL env for a composed Hydra root config, in the traffic of `scenario_node`."""
    import torch

    from ..observations import ObservationConfig
    from ..simulator.loading import scenario_config, simulator_config
    from .torchrl_env import HeterogeneousHighwayEnv

    sim_cfg = simulator_config(cfg.simulator)
    scenario = scenario_config(scenario_node, sim_cfg)
    obs_cfg = ObservationConfig.from_config(cfg.observation, cfg.model.streams)
    return HeterogeneousHighwayEnv(sim_cfg, scenario, obs_cfg, n_envs=n_envs, device=torch.device(cfg.device),
                                   seed=seed)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ENV_ID", "HeterogeneousHighwayEnv", "HeterogeneousHighwayGymEnv", "HeterogeneousHighwayVectorEnv",
           "make_env", "register_envs"]
