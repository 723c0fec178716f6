"""Training checkpoints: atomic writes, and a training identity that refuses the wrong checkpoint.

A checkpoint is a plain dict saved with `torch.save`. It records the training identity
(`train_key.training_config` as flat dotted keys, and its `train_key`), so that a run never
silently continues, or evaluates, weights that came from another model or setting.
What a checkpoint holds, and what a resume restores, is described in `hgm_repro.learner`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch

from .config_tree import flatten
from .schema import JobConfig
from .train_key import EVALUATION_VERSION, train_key, training_config

CHECKPOINT_FORMAT = 1
# The files a training leaves in its checkpoint directory that evaluation may load.
FINAL_CHECKPOINT = "final.pt"  # the network at the end of training: the paper's protocol tests this one
BEST_CHECKPOINT = "best.pt"  # the network with the best validation return so far (validation on only)
EMA_CHECKPOINT = "ema.pt"  # the exponential moving average of the online weights (learner.ema_decay > 0)
# Every validation pass's network, VAL_CHECKPOINTS/<env steps>.pt (eval.keep_val_checkpoints), and the one
# reselection chose among the best of them (eval.checkpoint=reselected), with its record beside it.
VAL_CHECKPOINTS = "val"
RESELECTED_CHECKPOINT = "reselected.pt"
RESELECTION_RECORD = "reselection.json"
# The kept pass with the best return among those safe enough (eval.checkpoint=safest), with its record.
SAFEST_CHECKPOINT = "safest.pt"
SAFEST_RECORD = "safest.json"
LAST_CHECKPOINT = "last.pt"  # everything a resume needs, while training runs

# What evaluation reads of a checkpoint: the network and the identity `check_compatible` checks.
# best.pt and the logged artifacts hold only these; the optimiser and the replay memory (most of
# a finished training's bytes) stay in final.pt alone.
WEIGHTS_KEYS = ("format", "model", "train_key", "training_config", "finished", "env_steps", "updates",
                "network", "best_val_return", "val_return", "evaluation_version")

# What a network's weights depend on: evaluation needs only these to match.
ARCHITECTURE_KEYS = ("model.name", "model.network", "model.streams", "observation")


class CheckpointMismatchError(RuntimeError):
    """A checkpoint was written for another model or training config than the one asked for."""


def recorded_training_config(job: JobConfig) -> dict[str, Any]:
    """What a checkpoint records of `job`: its `training_config` as flat dotted keys."""
    return flatten(training_config(job))


def _differences(saved: dict[str, Any], wanted: dict[str, Any], limit: int = 8) -> str:
    keys = sorted(set(saved) | set(wanted))
    diffs = [f"{k}: {saved.get(k, '<absent>')!r} in the checkpoint, {wanted.get(k, '<absent>')!r} here"
             for k in keys if saved.get(k) != wanted.get(k)]
    more = f" (and {len(diffs) - limit} more)" if len(diffs) > limit else ""
    return "; ".join(diffs[:limit]) + more


def check_compatible(checkpoint: dict[str, Any], job: JobConfig, path: Path, strict: bool = True) -> None:
    """Stop with a message naming both sides when `checkpoint` does not belong to `job`.

    strict: the whole training config must match (resuming a run). Otherwise only the network's
    architecture and inputs must (evaluating weights in another scenario or with other test settings).
    """
    saved = checkpoint.get("training_config", {})
    wanted = recorded_training_config(job)
    if strict and saved.get("version") != wanted["version"]:
        raise CheckpointMismatchError(
            f"checkpoint {path} was trained under training identity version {saved.get('version')}, this code's is "
            f"{wanted['version']} (hgm_repro.contracts.train_key.TRAIN_KEY_VERSION says what changed): it cannot be "
            "resumed. Delete it, or use another checkpoint directory, to train again.")
    if not strict:
        saved = {k: v for k, v in saved.items() if k.startswith(ARCHITECTURE_KEYS)}
        wanted = {k: v for k, v in wanted.items() if k.startswith(ARCHITECTURE_KEYS)}
    if saved == wanted:
        return
    saved_model, wanted_model = checkpoint.get("model", "?"), job.model.name
    what = "another model" if saved_model != wanted_model else "another training config"
    raise CheckpointMismatchError(
        f"checkpoint {path} is from {what}: it was trained for model '{saved_model}' "
        f"(train_key {checkpoint.get('train_key', '?')}), but this run is model '{wanted_model}' "
        f"(train_key {train_key(job)}). Differences: "
        f"{_differences(saved, wanted)}. Use another checkpoint directory, or delete this checkpoint to start over.")


def save_checkpoint(state: dict[str, Any], path: Path) -> Path:
    """Write `state` to `path` atomically: a run killed mid-write leaves the previous file intact.

    Only the job holding the train_key's lock writes here, so another temporary file of the same
    name is what a killed writer left half-written: it is removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for stale in path.parent.glob(f".{path.name}.tmp-*"):
        stale.unlink(missing_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "wb") as file:
        torch.save(state, file)
        file.flush()
        os.fsync(file.fileno())  # on disk before the rename makes it the checkpoint
    os.replace(tmp, path)
    return path


def weights_only(state: dict[str, Any]) -> dict[str, Any]:
    """The part of a checkpoint that evaluation loads (see `WEIGHTS_KEYS`)."""
    return {k: state[k] for k in WEIGHTS_KEYS if k in state}


def save_final(state: dict[str, Any], checkpoint_dir: Path) -> Path:
    """Write a finished training's `final.pt`, then drop `last.pt`, which it supersedes: the full
    state (replay memory included) is kept once. Killed between the two, `final.pt` already exists
    and is what a rerun returns."""
    final = save_checkpoint(state, Path(checkpoint_dir) / FINAL_CHECKPOINT)
    (Path(checkpoint_dir) / LAST_CHECKPOINT).unlink(missing_ok=True)
    return final


def chosen_by_current_validation(checkpoint: dict[str, Any]) -> bool:
    """Whether a validation-chosen checkpoint (best.pt, a kept pass) was scored by this code's
    validation: `evaluation_version` 1 (absent) handed hosts blank frames (train_key.EVALUATION_VERSION)."""
    return checkpoint.get("evaluation_version", 1) == EVALUATION_VERSION


def val_checkpoint_path(checkpoint_dir: Path, env_steps: int) -> Path:
    """Where a validation pass at `env_steps` keeps its network (zero-padded: the names sort by step)."""
    return Path(checkpoint_dir) / VAL_CHECKPOINTS / f"{env_steps:09d}.pt"


def weights_file(checkpoint: Path, directory: Path) -> Path:
    """`checkpoint` as a weights-only copy in `directory` (what an artifact needs). A file this
    version cannot read is returned as it is: evaluating it reports the problem."""
    try:
        state = load_checkpoint(checkpoint)
    except CheckpointMismatchError:
        return Path(checkpoint)
    return save_checkpoint(weights_only(state), Path(directory) / Path(checkpoint).name)


def load_checkpoint(path: Path, job: JobConfig | None = None, strict: bool = True,
                    map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Read a checkpoint; with `job`, refuse one that does not belong to it (see `check_compatible`)."""
    path = Path(path)
    # weights_only=False: the checkpoint also holds RNG states, schedules and (maybe) the replay
    # buffer, which are not plain tensors. Only load checkpoints this project wrote.
    try:
        checkpoint = torch.load(path, map_location=map_location, weights_only=False)
    except Exception as error:  # truncated, not a torch file, or pickled classes that no longer exist
        raise CheckpointMismatchError(
            f"checkpoint {path} cannot be read ({type(error).__name__}: {str(error)[:200]}): it is not a complete "
            f"checkpoint of this version of hgm_repro. Delete it to start that training over.") from error
    found = checkpoint.get("format") if isinstance(checkpoint, dict) else None
    if found != CHECKPOINT_FORMAT:
        raise CheckpointMismatchError(
            f"checkpoint {path} was written by another version of hgm_repro (checkpoint format {found}; this "
            f"version reads format {CHECKPOINT_FORMAT}). Use the version that wrote it, or delete it to train again.")
    if job is not None:
        check_compatible(checkpoint, job, path, strict=strict)
    return checkpoint
