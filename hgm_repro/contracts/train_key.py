"""The training identity: `training_config`, everything that decides what training produces,
and `train_key`, its short hash.

Two jobs with the same key would train the same network on the same data with the same
seed, so the second one reuses the first one's checkpoint (train once, evaluate many); a
checkpoint records the same `training_config` and refuses to resume under another one.
The test scenario, tracking, launcher and device are deliberately left out: they change
where a job evaluates or how fast it runs, not what it learns.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

from omegaconf import DictConfig

from .config_tree import plain
from .schema import JobConfig

# Bump when the checkpoint format or the meaning of a training config changes, so that
# old checkpoints are not silently reused by new code.
# 2: the simulator stopped paying R_o on crash steps and charges a crash to the decision it happens in
# (docs/interfaces.md): trainings of version 1 learned from other rewards and are not reused.
# 3: the config's groups by concern (eval, runtime and logging apart from learner): the identity hashes
# whole groups, with no lists of keys left out; trainings of version 2 are not reused (a checkpoint of
# one is refused by name).
TRAIN_KEY_VERSION = 3
KEY_LENGTH = 12

# Bump when the test or validation procedure changes what it measures, so that a store's finished
# evaluations of before are not reused, and a best.pt chosen by the old validation is not tested as if
# chosen by the new one (checkpoints record it as `evaluation_version`).
# 2: an env that restarted an episode no longer handed every other host of the batch a blank (all-zero)
# camera and HGM for one decision (evaluation.episodes.run_episodes). Training is unchanged.
EVALUATION_VERSION = 2

# The groups a training depends on, hashed whole. `eval` (the test and validation), `runtime` (how
# a job runs: threads, compile, precision, grouping, the memory's layout), `logging`, `tracking`,
# `device` and `force_retrain` are not: one training serves every test of it, on any machine.
TRAINING_GROUPS = ("model", "observation", "learner", "simulator", "train_scenario", "seed")


def training_config(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    """The groups of the root config that training depends on, as plain resolved data.

    Read from the resolved tree (a `JobConfig`'s `resolved`), not from the typed fields, so that a
    `JobConfig` and the tree it came from have one key.
    """
    root = _root(cfg)
    return {"version": TRAIN_KEY_VERSION, **{group: root[group] for group in TRAINING_GROUPS}}


def _root(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    if isinstance(cfg, JobConfig):
        return cfg.resolved
    return dict(plain(cfg))


def train_key(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> str:
    """A short hex digest of `training_config(cfg)`; stable across runs and machines."""
    return _digest(training_config(cfg))


def _digest(payload: Mapping[str, Any]) -> str:
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:KEY_LENGTH]


# Root groups that say where results go, how a job runs (the device aside: its numbers may differ),
# or whether to train again, not what an evaluation measures.
NON_EVALUATION_GROUPS = frozenset({"tracking", "force_retrain", "hydra", "runtime", "logging"})


def evaluation_key(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> str:
    """The evaluation identity: a short digest of the whole job config except `NON_EVALUATION_GROUPS`.

    With the training run it evaluates, it names one evaluation: a job whose evaluation already
    FINISHED (a sweep run again after a crash, a requeued job) does not evaluate again.
    """
    return _digest({"evaluation_version": EVALUATION_VERSION,
                    **{k: v for k, v in _root(cfg).items() if k not in NON_EVALUATION_GROUPS}})
