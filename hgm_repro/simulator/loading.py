"""Build simulator and scenario configs from Hydra/OmegaConf nodes or YAML files."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from .. import CONF_DIR
from .config import ConfigError, ScenarioConfig, SimulatorConfig


def _plain(node: Any) -> Any:
    try:
        from omegaconf import DictConfig, ListConfig, OmegaConf

        if isinstance(node, (DictConfig, ListConfig)):
            return OmegaConf.to_container(node, resolve=True)
    except ImportError:  # pragma: no cover
        pass
    return node


def simulator_config(node: Mapping[str, Any] | None = None, **overrides: Any) -> SimulatorConfig:
    """The simulator config from a mapping (default: conf/simulator/highway.yaml) plus overrides."""
    raw = dict(_plain(node)) if node is not None else load_yaml("simulator", "highway")
    raw.update(overrides)
    return SimulatorConfig.from_mapping(raw)


def scenario_config(node: Mapping[str, Any] | str, simulator: SimulatorConfig) -> ScenarioConfig:
    """A scenario from a mapping or by name ('1'..'5', 'train')."""
    raw = load_yaml("scenario", str(node)) if isinstance(node, (str, int)) else dict(_plain(node))
    return ScenarioConfig.from_mapping(raw, simulator)


def available(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


def load_yaml(group: str, name: str) -> dict[str, Any]:
    path = Path(CONF_DIR) / group / f"{name}.yaml"
    if not path.exists():
        raise ConfigError(f"unknown {group} {name!r}; allowed: {available(group)}")
    return yaml.safe_load(path.read_text())
