"""The paper's five-lane heterogeneous highway as a batched torch simulator.

The configs are imported at once; the torch parts when first used, so that validating a job's
config (`hgm_repro.contracts.schema`) answers without loading torch.
"""

from importlib import import_module
from typing import Any

from ..contracts.simulator_config import (
    ConfigError,
    RewardConfig,
    SafetyConfig,
    ScenarioConfig,
    SimulatorConfig,
    VehicleType,
)

_LAZY = {
    "HighwaySimulator": ".highway", "StepResult": ".highway", "episode_metrics": ".highway",
    "RewardTerms": ".reward", "speed_reward": ".reward",
    "HOST": ".state", "N_ACTIONS": ".state", "Action": ".state", "TrafficState": ".state",
}

__all__ = [
    "Action", "ConfigError", "HOST", "HighwaySimulator", "N_ACTIONS", "RewardConfig", "RewardTerms",
    "SafetyConfig", "ScenarioConfig", "SimulatorConfig", "StepResult", "TrafficState", "VehicleType",
    "episode_metrics", "speed_reward",
]


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value
