"""The paper's five-lane heterogeneous highway as a batched torch simulator."""

from .config import ConfigError, RewardConfig, SafetyConfig, ScenarioConfig, SimulatorConfig, VehicleType
from .highway import HighwaySimulator, StepResult, episode_metrics
from .reward import RewardTerms, speed_reward
from .state import HOST, N_ACTIONS, Action, TrafficState

__all__ = [
    "Action", "ConfigError", "HOST", "HighwaySimulator", "N_ACTIONS", "RewardConfig", "RewardTerms",
    "SafetyConfig", "ScenarioConfig", "SimulatorConfig", "StepResult", "TrafficState", "VehicleType",
    "episode_metrics", "speed_reward",
]
