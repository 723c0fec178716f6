"""The safest choice (`eval.checkpoint=safest`): the tested network chosen among the kept validation
passes by a return that counts only while the pass stays safe.

best.pt is the pass with the highest validation return, whatever it cost in crashes; a host that
races to a high return and crashes one episode in five can win it. Here every kept pass
(`eval.keep_val_checkpoints`) drives `eval.safest_envs x ceil(safest_episodes / safest_envs)`
greedy episodes on the validation traffic (the training traffic from seed + VAL_SEED_OFFSET, as
validation), at least `SAFEST_MIN_EPISODES` (256): a pass's own validation is a few dozen episodes and
records no collisions, so every pass is driven again. Among the passes with fewer collisions per
episode than `eval.safest_max_collisions`, the best mean return wins and is kept as `safest.pt`, with
a record of every pass (`safest.json`). The drives are made once per training and options; another
bar re-picks from them. When no pass is under the bar, or no pass was kept, the test is refused with
a message. Either outcome can be written on the training run (`outcome_tags`), so that a store says which
trainings were refused, not only which were tested.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import torch
from filelock import FileLock

from ..contracts.checkpoint import SAFEST_CHECKPOINT, SAFEST_RECORD, VAL_CHECKPOINTS, load_checkpoint, save_checkpoint
from ..contracts.errors import ConfigError
from ..contracts.interrupts import acquire_stoppably
from ..contracts.names import SAFEST_REFUSED, SAFEST_TAGS, VAL_SEED_OFFSET
from ..contracts.schema import JobConfig
from ..envs import make_env
from .episodes import learned_policy, run_episodes
from .reselection import ValidationPass, validation_passes, write_json


def drive_options(job: JobConfig) -> dict[str, Any]:
    """What decides the drives besides the training: drives made under other options are redone."""
    envs = job.eval.safest_envs
    return {"envs": envs, "episodes_per_env": math.ceil(job.eval.safest_episodes / envs),
            "traffic": job.train_scenario.name, "traffic_seed": job.seed + VAL_SEED_OFFSET}


class SafestRefused(ConfigError):
    """No kept pass stays under the bar: the test is refused. `record` holds every pass's drive."""

    def __init__(self, message: str, record: dict[str, Any]):
        super().__init__(message)
        self.record = record


def outcome_tags(record: dict[str, Any]) -> dict[str, str]:
    """The training run's tags (SAFEST_TAGS) for a safest record: the chosen pass's env steps or "refused",
    the bar, and the fewest collisions per episode any pass had."""
    chosen = record.get("chosen_env_steps")
    lowest = min(r["collisions"] for r in record["candidates"])
    values = (SAFEST_REFUSED if chosen is None else str(chosen), str(record["max_collisions"]), f"{lowest:.4f}")
    return dict(zip(SAFEST_TAGS, values, strict=True))


def pick_safest(rows: list[dict[str, Any]], max_collisions: float) -> dict[str, Any] | None:
    """The row with the best `return` among those with `collisions` under `max_collisions` (ties: the
    earlier pass, the order of `rows`), or None when none is under it."""
    safe = [r for r in rows if r["collisions"] < max_collisions]
    return max(safe, key=lambda r: r["return"]) if safe else None


def choose_safest(job: JobConfig, checkpoint_dir: Path) -> tuple[Path, dict[str, Any]]:
    """`checkpoint_dir/safest.pt` and its record (drive options, every pass's return and collisions, the
    bar, the chosen env step). Concurrent tests of one training wait for the first one's drives."""
    checkpoint_dir = Path(checkpoint_dir)
    lock = FileLock(str(checkpoint_dir / "safest.lock"))
    acquire_stoppably(lock, 1.0)
    try:
        passes = validation_passes(checkpoint_dir)
        if not passes:
            raise ConfigError(
                f"eval.checkpoint=safest, but {checkpoint_dir / VAL_CHECKPOINTS} holds no validation pass's network: "
                "the training ran with eval.keep_val_checkpoints=false (or without validation). Train again with "
                "eval.keep_val_checkpoints=true force_retrain=true, or test eval.checkpoint=best.")
        options, kept = drive_options(job), [p.path.name for p in passes]
        record_path = checkpoint_dir / SAFEST_RECORD
        record = json.loads(record_path.read_text()) if record_path.is_file() else {}
        if record.get("options") != options or record.get("passes") != kept:
            record = {"options": options, "passes": kept, "candidates": _drive(job, passes, options)}
        bar = job.eval.safest_max_collisions
        chosen = pick_safest(record["candidates"], bar)
        record.update(max_collisions=bar, chosen_env_steps=None if chosen is None else chosen["env_steps"])
        write_json(record, record_path)
        if chosen is None:
            lowest = min(record["candidates"], key=lambda r: r["collisions"])
            raise SafestRefused(
                f"eval.checkpoint=safest: no validation pass of {checkpoint_dir} stays under "
                f"eval.safest_max_collisions={bar} collisions per episode on {lowest['episodes']} validation episodes "
                f"(the safest, at {lowest['env_steps']} env steps, had {lowest['collisions']:.3f}; every pass in "
                f"{record_path}). Raise the bar, or test eval.checkpoint=best.", record)
        winner = next(p for p in passes if p.env_steps == chosen["env_steps"])
        chosen_path = checkpoint_dir / SAFEST_CHECKPOINT
        save_checkpoint({**load_checkpoint(winner.path), "safest_from": winner.env_steps}, chosen_path)
        return chosen_path, record
    finally:
        lock.release()


@torch.no_grad()
def _drive(job: JobConfig, passes: list[ValidationPass], options: dict[str, Any]) -> list[dict[str, Any]]:
    if job.runtime.torch_threads > 0:
        torch.set_num_threads(job.runtime.torch_threads)
    device = torch.device(job.device)
    env = make_env(job, job.train_scenario, n_envs=options["envs"], seed=options["traffic_seed"])
    rows = []
    try:
        for kept in passes:
            episodes = run_episodes(env, learned_policy(job, kept.path, device), options["episodes_per_env"],
                                    options["traffic_seed"])
            rows.append({"env_steps": kept.env_steps, "val_return": kept.val_return,
                         "return": float(episodes["episode_return"].mean()),
                         "collisions": float(episodes["collisions"].mean()), "episodes": len(episodes)})
    finally:
        env.close()
    return rows

