"""Greedy evaluation of a host policy (learned or a driver) in a scenario, and its GIFs."""

from .episodes import EPISODE_METRICS, EvaluationResult, evaluate

__all__ = ["EPISODE_METRICS", "EvaluationResult", "evaluate"]
