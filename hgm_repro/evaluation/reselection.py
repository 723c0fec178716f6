"""Reselection (`eval.checkpoint=reselected`): the network the test drives, chosen again among the
best validation passes.

best.pt is the pass with the highest validation mean, each a mean over `eval.val_envs x val_episodes`
episodes whose returns spread by 100 or more; the highest of eight such means is partly the luckiest
pass (the winner's curse). Reselection takes the `eval.reselect_top` passes with the highest
validation return (their networks kept by `eval.keep_val_checkpoints`), drives each greedily on
`reselect_envs x reselect_episodes` episodes of fresh validation traffic (the training traffic from
seed + RESELECT_SEED_OFFSET, which neither validation nor any test draws), and keeps the one with the
best mean return as `reselected.pt`, with a record of every candidate (`reselection.json`). The
choice is made once per training and options; later tests of the same training reuse it. Passes
whose validation handed hosts blank frames (evaluation version 1) are all candidates, unranked.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from filelock import FileLock

from ..contracts.checkpoint import (
    BEST_CHECKPOINT,
    RESELECTED_CHECKPOINT,
    RESELECTION_RECORD,
    VAL_CHECKPOINTS,
    chosen_by_current_validation,
    load_checkpoint,
    save_checkpoint,
)
from ..contracts.errors import ConfigError
from ..contracts.interrupts import acquire_stoppably
from ..contracts.names import RESELECT_SEED_OFFSET, VAL_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..contracts.train_key import EVALUATION_VERSION
from ..envs import make_env
from .episodes import learned_policy, run_episodes


@dataclass(frozen=True)
class ValidationPass:
    """A validation pass's network (`path`), the env step it ran at and its validation mean return."""

    env_steps: int
    val_return: float
    path: Path
    current: bool  # scored by this code's validation (not the blank-frame one of evaluation version 1)


def validation_passes(checkpoint_dir: Path) -> list[ValidationPass]:
    """The validation passes a training kept (`eval.keep_val_checkpoints`), in the order of its steps."""
    passes = []
    for path in sorted((Path(checkpoint_dir) / VAL_CHECKPOINTS).glob("*.pt")):
        state = load_checkpoint(path)
        passes.append(ValidationPass(int(state["env_steps"]), float(state["val_return"]), path,
                                     chosen_by_current_validation(state)))
    return passes


def best_pass(passes: list[ValidationPass], budget: int | None = None) -> ValidationPass:
    """The pass best.pt holds (the highest validation return, the first of equals, as training keeps it),
    or, with `budget`, the one best.pt would hold had the training stopped after `budget` env steps."""
    within = [p for p in passes if budget is None or p.env_steps <= budget]
    if not within:
        raise ConfigError(f"no validation pass at or before {budget} env steps; the passes ran at "
                          f"{[p.env_steps for p in passes]}")
    return max(within, key=lambda p: p.val_return)


def reselection_options(job: JobConfig) -> dict[str, Any]:
    """What decides a reselection besides the training: a record made under other options is redone."""
    return {"top": job.eval.reselect_top, "envs": job.eval.reselect_envs, "episodes": job.eval.reselect_episodes,
            "traffic": job.train_scenario.name, "traffic_seed": job.seed + RESELECT_SEED_OFFSET}


def reselect(job: JobConfig, checkpoint_dir: Path) -> tuple[Path, dict[str, Any]]:
    """`checkpoint_dir/reselected.pt` and its record (options, candidates, the chosen env step),
    computed now unless a record under the same options and passes exists. Concurrent tests of one
    training (a grid's scenarios) wait for the first one's choice instead of repeating it."""
    checkpoint_dir = Path(checkpoint_dir)
    chosen_path = checkpoint_dir / RESELECTED_CHECKPOINT
    record_path = checkpoint_dir / RESELECTION_RECORD
    lock = FileLock(str(checkpoint_dir / "reselect.lock"))
    acquire_stoppably(lock, 1.0)
    try:
        passes = validation_passes(checkpoint_dir)
        if not passes:
            raise ConfigError(
                f"eval.checkpoint=reselected, but {checkpoint_dir / VAL_CHECKPOINTS} holds no validation pass's "
                "network: the training ran with eval.keep_val_checkpoints=false (or without validation). Train "
                "again with eval.keep_val_checkpoints=true force_retrain=true, or test eval.checkpoint=best.")
        options = reselection_options(job)
        kept = [p.path.name for p in passes]
        if record_path.is_file() and chosen_path.is_file():
            record = json.loads(record_path.read_text())
            if record.get("options") == options and record.get("passes") == kept \
                    and record.get("ranked_by_validation") == all(p.current for p in passes):
                return chosen_path, record
        record = _choose(job, passes, options)
        record["passes"] = kept
        winner = next(p for p in passes if p.env_steps == record["chosen_env_steps"])
        save_checkpoint({**load_checkpoint(winner.path), "reselected_from": winner.env_steps}, chosen_path)
        write_json(record, record_path)
        return chosen_path, record
    finally:
        lock.release()


@torch.no_grad()
def _choose(job: JobConfig, passes: list[ValidationPass], options: dict[str, Any]) -> dict[str, Any]:
    """Drive the `top` best passes on the reselection traffic; the best mean return wins (ties: the
    pass with the higher validation return, then the earlier one). Passes scored by an older
    validation (blank frames, evaluation version 1) are not ranked by it: every one is a candidate."""
    if job.runtime.torch_threads > 0:
        torch.set_num_threads(job.runtime.torch_threads)
    device = torch.device(job.device)
    ranked = all(p.current for p in passes)
    candidates = sorted(passes, key=lambda p: (-p.val_return, p.env_steps))[: options["top"]] if ranked else passes
    env = make_env(job, job.train_scenario, n_envs=options["envs"], seed=options["traffic_seed"])
    rows = []
    try:
        for candidate in candidates:
            episodes = run_episodes(env, learned_policy(job, candidate.path, device), options["episodes"],
                                    options["traffic_seed"])
            rows.append({"env_steps": candidate.env_steps, "val_return": candidate.val_return,
                         "return": float(episodes["episode_return"].mean()),
                         "collisions": float(episodes["collisions"].mean()), "episodes": len(episodes)})
    finally:
        env.close()
    best = max(rows, key=lambda r: r["return"])  # max keeps the first of equals: candidates' order
    return {"options": options, "ranked_by_validation": ranked, "candidates": rows,
            "chosen_env_steps": best["env_steps"]}


def write_json(payload: dict[str, Any], path: Path) -> None:
    """A choice's record, replaced whole (a reader never sees half of it)."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(payload, indent=2))
    os.replace(tmp, path)


@torch.no_grad()
def revalidate(job: JobConfig, checkpoint_dir: Path) -> list[ValidationPass]:
    """Score every kept pass again with this code's validation (`eval.val_envs x val_episodes` greedy
    episodes on the validation traffic, as training does) and choose best.pt afresh from those scores:
    for a training whose validation predates evaluation version 2, without training again. The passes
    keep their new scores (so reselection ranks them); returns them."""
    checkpoint_dir = Path(checkpoint_dir)
    passes = validation_passes(checkpoint_dir)
    if not passes:
        raise ConfigError(f"{checkpoint_dir / VAL_CHECKPOINTS} holds no validation pass's network: the training ran "
                          "with eval.keep_val_checkpoints=false, so its best.pt cannot be chosen again.")
    if job.runtime.torch_threads > 0:
        torch.set_num_threads(job.runtime.torch_threads)
    device, traffic = torch.device(job.device), job.seed + VAL_SEED_OFFSET
    env = make_env(job, job.train_scenario, n_envs=job.eval.val_envs, seed=traffic)
    scored = []
    try:
        for kept in passes:
            policy = learned_policy(job, kept.path, device)
            score = float(run_episodes(env, policy, job.eval.val_episodes, traffic)["episode_return"].mean())
            state = load_checkpoint(kept.path)
            save_checkpoint({**state, "val_return": score, "evaluation_version": EVALUATION_VERSION}, kept.path)
            scored.append(ValidationPass(kept.env_steps, score, kept.path, True))
    finally:
        env.close()
    best = best_pass(scored)
    save_checkpoint({**load_checkpoint(best.path), "best_val_return": best.val_return,
                     "evaluation_version": EVALUATION_VERSION}, checkpoint_dir / BEST_CHECKPOINT)
    return scored
