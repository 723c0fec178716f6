"""Environments over the batched simulator: TorchRL (the fast path) and Gymnasium (one env)."""

from __future__ import annotations

from typing import Any

import torch


def make_env(cfg: Any, scenario_node: Any, n_envs: int, seed: int) -> Any:
    """The TorchRL env for a composed Hydra root config, in the traffic of `scenario_node`."""
    from ..observations import ObservationConfig
    from ..simulator.loading import scenario_config, simulator_config
    from .torchrl_env import HeterogeneousHighwayEnv

    sim_cfg = simulator_config(cfg.simulator)
    scenario = scenario_config(scenario_node, sim_cfg)
    obs_cfg = ObservationConfig.from_config(cfg.observation, cfg.model.streams)
    return HeterogeneousHighwayEnv(sim_cfg, scenario, obs_cfg, n_envs=n_envs, device=torch.device(cfg.device),
                                   seed=seed)


from .gym_env import ENV_ID, HeterogeneousHighwayGymEnv, register_envs  # noqa: E402

register_envs()

__all__ = ["ENV_ID", "HeterogeneousHighwayGymEnv", "make_env", "register_envs"]
