"""The simulator, scenario and observation configs built from the Hydra config files (or from any
mapping): the simulator and the observation builders themselves never read a file."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .conf_dir import load_yaml
from .config_tree import plain
from .observation_config import STREAM_KEYS, ObservationConfig
from .simulator_config import ScenarioConfig, SimulatorConfig


def simulator_config(node: Mapping[str, Any] | None = None, **overrides: Any) -> SimulatorConfig:
    """The simulator config from a mapping (default: conf/simulator/highway.yaml) plus overrides."""
    raw = dict(plain(node)) if node is not None else load_yaml("simulator", "highway")
    raw.update(overrides)
    return SimulatorConfig.from_mapping(raw)


def scenario_config(node: Mapping[str, Any] | str, simulator: SimulatorConfig) -> ScenarioConfig:
    """A scenario from a mapping or by name ('1'..'5', 'train')."""
    raw = load_yaml("scenario", str(node)) if isinstance(node, (str, int)) else dict(plain(node))
    return ScenarioConfig.from_mapping(raw, simulator)


def observation_node() -> dict[str, Any]:
    """The root config's `observation` node (conf/config.yaml), read without Hydra."""
    return dict(load_yaml("", "config")["observation"])


def observation_config(streams: Mapping[str, Any] | str, **overrides: Any) -> ObservationConfig:
    """The observation config of the defaults (conf/config.yaml's `observation` node) plus overrides,
    for the streams of a model: its name ('proposed', 'min', ...) or a `streams` mapping. An override
    of a stream (camera, hgm, coordinates) replaces the model's."""
    streams_node = load_yaml("model", streams)["streams"] if isinstance(streams, str) else dict(streams)
    streams_node.update({k: overrides.pop(k) for k in STREAM_KEYS if k in overrides})
    return ObservationConfig.from_config({**observation_node(), **overrides}, streams_node)
