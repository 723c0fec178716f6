"""Config trees as plain data: a Hydra node resolved into dicts and lists, and nested configs as flat
`a.b.c` keys (for MLflow params, checkpoints and reports)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf


def plain(node: Any) -> Any:
    """An OmegaConf node resolved into plain dicts and lists; anything else as it is."""
    if isinstance(node, (DictConfig, ListConfig)):
        return OmegaConf.to_container(node, resolve=True)
    return node


def flatten(node: Any, prefix: str = "") -> dict[str, Any]:
    """`{'a': {'b': 1}}` -> `{'a.b': 1}`; an OmegaConf node is resolved first. Empty mappings stay leaves."""
    node = plain(node)
    flat: dict[str, Any] = {}
    for key, value in node.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat
