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

from omegaconf import DictConfig, OmegaConf

from .schema import JobConfig

# Bump when the checkpoint format or the meaning of a training config changes, so that
# old checkpoints are not silently reused by new code.
# 2: the simulator stopped paying R_o on crash steps and charges a crash to the decision it happens in
# (docs/interfaces.md): trainings of version 1 learned from other rewards and are not reused.
TRAIN_KEY_VERSION = 2
KEY_LENGTH = 12

# Learner values that change how a run is measured or run, not the trained weights: they may
# differ between a checkpoint and the run that resumes or evaluates it. `compile`, `cuda_graph`
# and `torch_threads` are execution strategies like `device`.
NON_TRAINING_LEARNER_KEYS = frozenset(
    {"test_steps", "test_envs", "log_every", "checkpoint_every", "compile", "cuda_graph",
     "checkpoint_buffer_max_mb", "torch_threads", "eval_every", "val_envs", "val_episodes",
     "grouped", "replay_frames"}
)
# Learner values added after trainings were stored, at the value that trains as before: left out
# of the key at that value, so that existing trainings keep their keys.
LEARNER_KEYS_ADDED_LATER = {"update_dtype": "float32", "eps_floor": 0.0, "eps_floor_steps": 0,
                            "random_lane_change_share": 0.4, "adam_eps": 1e-8, "target_tau": 0.0, "ema_decay": 0.0,
                            "replay_frames": False}
# Observation values added after trainings were stored, likewise (the paper's HGM at these values).
OBSERVATION_KEYS_ADDED_LATER = {"hgm_ahead": 0.0, "hgm_host_cell": "paper"}
# Model values that name or describe the model without changing its training.
MODEL_KEYS_IN_KEY = ("name", "learned", "streams", "network", "driver")
# Modules that moved after trainings were stored (new prefix -> the prefix the key was defined
# with): a network's `_target_` is hashed under its old path, so that a move keeps every key.
MOVED_TARGETS = {"hgm_repro.models.networks.": "hgm_repro.networks."}


def _stable_target(node: Any) -> Any:
    if not isinstance(node, Mapping) or not isinstance(node.get("_target_"), str):
        return node
    target = node["_target_"]
    for new, old in MOVED_TARGETS.items():
        if target.startswith(new):
            return {**node, "_target_": old + target[len(new):]}
    return node


def training_config(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    """The part of the root config that training depends on, as plain resolved data.

    Read from the resolved tree (a `JobConfig`'s `resolved`), not from the typed fields, so
    that keys no schema names (and the defaults a schema fills in) leave the key as it was.
    """
    if isinstance(cfg, JobConfig):
        root = cfg.resolved
    else:
        root = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    model = root["model"]
    learner = {k: v for k, v in root["learner"].items() if k not in NON_TRAINING_LEARNER_KEYS
               and LEARNER_KEYS_ADDED_LATER.get(k, object()) != v}
    return {
        "version": TRAIN_KEY_VERSION,
        "model": {k: _stable_target(model[k]) if k == "network" else model[k] for k in MODEL_KEYS_IN_KEY if k in model},
        "observation": {k: v for k, v in root["observation"].items()
                        if OBSERVATION_KEYS_ADDED_LATER.get(k, object()) != v},
        "learner": learner,
        "simulator": root["simulator"],
        "train_scenario": root["train_scenario"],
        "seed": root["seed"],
    }


def train_key(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> str:
    """A short hex digest of `training_config(cfg)`; stable across runs and machines."""
    payload = json.dumps(training_config(cfg), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(payload.encode()).hexdigest()[:KEY_LENGTH]


# Root keys that say where results go or whether to train again, not what an evaluation measures.
NON_EVALUATION_KEYS = frozenset({"tracking", "force_retrain", "hydra"})
NON_EVALUATION_LEARNER_KEYS = frozenset({"grouped"})


def evaluation_key(cfg: JobConfig | DictConfig | Mapping[str, Any]) -> str:
    """The evaluation identity: a short digest of the whole job config except `NON_EVALUATION_KEYS`.

    With the training run it evaluates, it names one evaluation: a job whose evaluation already
    FINISHED (a sweep run again after a crash, a requeued job) does not evaluate again.
    """
    if isinstance(cfg, JobConfig):
        root = cfg.resolved
    else:
        root = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    payload = {k: v for k, v in root.items() if k not in NON_EVALUATION_KEYS}
    if isinstance(payload.get("learner"), Mapping):
        # How the training was scheduled is not what an evaluation measures: a grouped sweep finds
        # the evaluations of a solo one (and those of stores written before the setting existed).
        payload["learner"] = {k: v for k, v in payload["learner"].items() if k not in NON_EVALUATION_LEARNER_KEYS
                              and LEARNER_KEYS_ADDED_LATER.get(k, object()) != v}
    if isinstance(payload.get("observation"), Mapping):
        payload["observation"] = {k: v for k, v in payload["observation"].items()
                                  if OBSERVATION_KEYS_ADDED_LATER.get(k, object()) != v}
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:KEY_LENGTH]
