"""Where the Hydra configs live, and the simulator and scenario configs built from them (or from any
mapping): the simulator itself never reads a file."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError
from .simulator_config import ScenarioConfig, SimulatorConfig

PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def find_conf_dir(package_root: Path | None = None) -> Path:
    """The Hydra configs: `hgm_repro/conf` in an installed wheel (setup.py maps the repository's
    `conf/` there), else `conf/` beside the package in a checkout or an editable install."""
    root = PACKAGE_ROOT if package_root is None else package_root
    candidates = (root / "conf", root.parent / "conf")
    for candidate in candidates:
        if (candidate / "config.yaml").is_file():
            return candidate
    raise FileNotFoundError(f"hgm_repro's configs are missing: none of {[str(c) for c in candidates]} holds "
                            "config.yaml; reinstall the package (pip install .) or run from a checkout")


CONF_DIR = find_conf_dir()


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
