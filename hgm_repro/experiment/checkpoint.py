"""Training checkpoints: atomic writes, and a config fingerprint that refuses the wrong checkpoint.

A checkpoint is a plain dict saved with `torch.save`. It records the *training config* (the
parts of the composed Hydra config that change what is learned: model name and network,
observation, learner, simulator, training traffic, seed) and its fingerprint, so that a run
never silently continues, or evaluates, weights that came from another model or setting.
What a checkpoint holds, and what a resume restores, is described in `hgm_repro.learner`.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf

from .config_tree import flatten

CHECKPOINT_FORMAT = 1

# Learner keys that change how a run is measured or run, not what it learns: they may differ
# between a checkpoint and the run that resumes or evaluates it.
NON_TRAINING_LEARNER_KEYS = ("test_steps", "test_envs", "log_every", "checkpoint_every", "compile",
                             "cuda_graph", "checkpoint_buffer_max_mb", "torch_threads")

# What a network's weights depend on: evaluation needs only these to match.
ARCHITECTURE_KEYS = ("model.name", "model.network", "model.streams", "observation")


class CheckpointMismatchError(RuntimeError):
    """A checkpoint was written for another model or training config than the one asked for."""


def _plain(node: Any) -> Any:
    if isinstance(node, DictConfig):
        return OmegaConf.to_container(node, resolve=True)
    return node


def training_config(cfg: DictConfig) -> dict[str, Any]:
    """The parts of the root config that define a training run (flat dotted keys, plain values)."""
    learner = {k: v for k, v in _plain(cfg.learner).items() if k not in NON_TRAINING_LEARNER_KEYS}
    tree = {
        "model": {"name": cfg.model.name, "network": _plain(cfg.model.get("network")),
                  "streams": _plain(cfg.model.get("streams"))},
        "observation": _plain(cfg.observation),
        "learner": learner,
        "simulator": _plain(cfg.simulator),
        "train_scenario": _plain(cfg.train_scenario),
        "seed": cfg.seed,
    }
    return flatten(tree)


def config_fingerprint(config: dict[str, Any]) -> str:
    """A short stable hash of a `training_config` dict."""
    blob = json.dumps(config, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _differences(saved: dict[str, Any], wanted: dict[str, Any], limit: int = 8) -> str:
    keys = sorted(set(saved) | set(wanted))
    diffs = [f"{k}: {saved.get(k, '<absent>')!r} in the checkpoint, {wanted.get(k, '<absent>')!r} here"
             for k in keys if saved.get(k) != wanted.get(k)]
    more = f" (and {len(diffs) - limit} more)" if len(diffs) > limit else ""
    return "; ".join(diffs[:limit]) + more


def check_compatible(checkpoint: dict[str, Any], cfg: DictConfig, path: Path, strict: bool = True) -> None:
    """Stop with a message naming both sides when `checkpoint` does not belong to `cfg`.

    strict: the whole training config must match (resuming a run). Otherwise only the network's
    architecture and inputs must (evaluating weights in another scenario or with other test settings).
    """
    saved = checkpoint.get("training_config", {})
    wanted = training_config(cfg)
    if not strict:
        saved = {k: v for k, v in saved.items() if k.startswith(ARCHITECTURE_KEYS)}
        wanted = {k: v for k, v in wanted.items() if k.startswith(ARCHITECTURE_KEYS)}
    if saved == wanted:
        return
    saved_model, wanted_model = checkpoint.get("model", "?"), cfg.model.name
    what = "another model" if saved_model != wanted_model else "another training config"
    raise CheckpointMismatchError(
        f"checkpoint {path} is from {what}: it was trained for model '{saved_model}' "
        f"(config fingerprint {checkpoint.get('fingerprint', '?')}), but this run is model '{wanted_model}' "
        f"(config fingerprint {config_fingerprint(training_config(cfg))}). Differences: "
        f"{_differences(saved, wanted)}. Use another checkpoint directory, or delete this checkpoint to start over.")


def save_checkpoint(state: dict[str, Any], path: Path) -> Path:
    """Write `state` to `path` atomically: a run killed mid-write leaves the previous file intact."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    torch.save(state, tmp)
    os.replace(tmp, path)
    return path


def load_checkpoint(path: Path, cfg: DictConfig | None = None, strict: bool = True,
                    map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Read a checkpoint; with `cfg`, refuse one that does not belong to it (see `check_compatible`)."""
    path = Path(path)
    # weights_only=False: the checkpoint also holds RNG states, schedules and (maybe) the replay
    # buffer, which are not plain tensors. Only load checkpoints this project wrote.
    checkpoint = torch.load(path, map_location=map_location, weights_only=False)
    if checkpoint.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointMismatchError(f"{path} is not a hgm_repro checkpoint of format {CHECKPOINT_FORMAT}")
    if cfg is not None:
        check_compatible(checkpoint, cfg, path, strict=strict)
    return checkpoint
