"""Where the Hydra configs live, and plain reads of one config file: the bottom of the contracts
floor, so that any contract (Table 3's shape, the default configs) can read its one definition."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError

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


def available(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


def load_yaml(group: str, name: str) -> dict[str, Any]:
    path = Path(CONF_DIR) / group / f"{name}.yaml"
    if not path.exists():
        raise ConfigError(f"unknown {group} {name!r}; allowed: {available(group)}")
    return yaml.safe_load(path.read_text())
