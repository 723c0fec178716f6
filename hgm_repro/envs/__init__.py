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


def make_env(job: Any, scenario: Any, n_envs: int, seed: int) -> Any:
    """The TorchRL env for `job` (a validated `JobConfig`) in the traffic of `scenario` (a `ScenarioConfig`,
    usually `job.scenario` or `job.train_scenario`)."""
    import torch

    from .torchrl_env import HeterogeneousHighwayEnv

    return HeterogeneousHighwayEnv(job.simulator, scenario, job.observation, n_envs=n_envs,
                                   device=torch.device(job.device), seed=seed)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ENV_ID", "HeterogeneousHighwayEnv", "HeterogeneousHighwayGymEnv", "HeterogeneousHighwayVectorEnv",
           "make_env", "register_envs"]
