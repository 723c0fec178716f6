"""The Gymnasium id of the heterogeneous highway and its registration.

Kept apart from the env classes so that registering (on `import hgm_repro`) imports only
Gymnasium: the entry points are strings, loaded when an env is made.
"""

from __future__ import annotations

import gymnasium as gym

ENV_ID = "hgm_repro/HeterogeneousHighway-v0"


def register_envs() -> None:
    """Register the env (one env and its batched VectorEnv); calling it again does nothing."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="hgm_repro.envs.gym_env:HeterogeneousHighwayGymEnv",
                     vector_entry_point="hgm_repro.envs.gym_vector_env:HeterogeneousHighwayVectorEnv")
