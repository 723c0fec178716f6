"""The trainings service: a job gets its trained network from `obtain_training`, for its seed alone or
with the other seeds of its model that its sweep trains together (`runtime.grouped`).

Train once, evaluate many: training depends only on the training config (`train_key`), so a sweep over
test scenarios trains each model and seed once. One call goes

1. lock: the key's one trainer holds `checkpoints/<train_key>/train.lock`; the others wait on it. A
   group's first job also holds the group's lock (`checkpoints/groups/<group>.lock`) and the lock of
   every other seed it can get, so that the group's other jobs wait for it instead of training alone;
2. reuse: a FINISHED training run with the key in the store is not trained again (its checkpoint is on
   disk or fetched from the store); a run that stopped before it finished (its id is kept beside the
   checkpoints) is resumed from `last.pt`, in the same MLflow run; a job whose test of a finished
   training has finished needs no network at all (`tested_training`);
3. open run: one MLflow training run per seed, tagged and described alike alone or in a group;
4. train: `learner.train` for one seed, `learner.train_group` for several (one process, one loop);
5. log: final.pt (and best.pt, ema.pt) as weights, the MLflow model and the checkpoint's path; each
   run ends FINISHED, KILLED (stopped by a signal) or FAILED.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout

from ..contracts.checkpoint import (
    BEST_CHECKPOINT,
    EMA_CHECKPOINT,
    FINAL_CHECKPOINT,
    LAST_CHECKPOINT,
    RESELECTED_CHECKPOINT,
    SAFEST_CHECKPOINT,
    VAL_CHECKPOINTS,
    chosen_by_current_validation,
    load_checkpoint,
    weights_file,
)
from ..contracts.errors import ConfigError
from ..contracts.interrupts import JobInterrupted, acquire_stoppably
from ..contracts.schema import JobConfig, check_config
from ..contracts.train_key import EVALUATION_VERSION, evaluation_key, train_key, training_config
from ..learner.grouped import group_key, use_grouped
from .descriptions import config_yaml, training_description
from .provenance import run_tags
from .store import Tracker, flatten

log = logging.getLogger(__name__)

LogFn = Callable[[dict[str, float], int], None]
TrainFn = Callable[[JobConfig, Path, LogFn], Path]
RUN_ID_FILE = "mlflow_run_id"  # beside the checkpoints: the training run a resume continues
CHECKPOINT_ARTIFACT = "checkpoint"
TRAINING_GROUPS_ENV = "HGM_REPRO_TRAINING_GROUPS"  # how a sweep tells its jobs which seeds train together
# Linear schedules computed in float32 (epsilon 0.775002 for 0.775): their curves need 4 decimals.
SCHEDULE_METRICS = ("train/epsilon", "train/beta")
SCHEDULE_DECIMALS = 4


@dataclass
class Training:
    how: str  # "trained", "resumed", "reused", or "none" (non-learning driver)
    run_id: str | None = None
    checkpoint: Path | None = None


@dataclass
class _Seed:
    """One seed's training as the service holds it: its job, key, checkpoint folder and a run to resume."""

    job: JobConfig
    key: str
    checkpoint_dir: Path
    unfinished: str | None = None  # the run id of a training that stopped before it finished


# --- which seeds train together -------------------------------------------------------------------


def group_id(job: JobConfig) -> str:
    """A short name of the group `job` trains in: its training identity without the seed."""
    return hashlib.sha256(group_key(job).encode()).hexdigest()[:12]


def plan_groups(jobs: Iterable[JobConfig]) -> dict[str, list[int]]:
    """A sweep's training groups: per group, the seeds of its learned jobs that `runtime.grouped` lets
    train together (two or more). A job that forces a retrain trains alone."""
    groups: dict[str, set[int]] = {}
    for job in jobs:
        if job.model.learned and not job.force_retrain and use_grouped(job.runtime.grouped, job.device):
            groups.setdefault(group_id(job), set()).add(job.seed)
    return {group: sorted(seeds) for group, seeds in groups.items() if len(seeds) > 1}


def group_of(job: JobConfig, plan: Mapping[str, list[int]]) -> list[JobConfig]:
    """`job` first, then the other seeds `plan` trains with it (none when it trains alone)."""
    seeds = [] if job.force_retrain else plan.get(group_id(job), [])
    return [job, *(check_config({**job.resolved, "seed": seed}) for seed in seeds if seed != job.seed)]


def read_plan(text: str | None) -> dict[str, list[int]]:
    return json.loads(text) if text else {}


# --- the service ----------------------------------------------------------------------------------


def obtain_training(
    members: list[JobConfig], tracker: Tracker, parent_run_id: str | None, train_fn: TrainFn | None = None,
) -> Training:
    """The finished training of `members[0]`: reused from the store, or resumed or trained now, together
    with those of the other `members` (other seeds of its group) that are neither finished nor held by
    another process."""
    job = members[0]
    with ExitStack() as held:
        if len(members) > 1:
            _hold(held, group_lock(tracker, job), f"the seeds {[m.seed for m in members]} of model "
                  f"'{job.model.name}' are being trained together by another job: waiting for it")
        seeds = []
        for member in members:
            key = train_key(member)
            lock, checkpoint_dir = training_lock(tracker, key)
            if member is job:
                _hold(held, lock, f"train_key={key} is being trained by another job: waiting for it")
            elif not _try_hold(held, lock):
                continue  # another process trains it; its jobs wait for that one
            seeds.append(_Seed(member, key, checkpoint_dir))
        found: dict[str, Training] = {}
        to_train = []
        for seed in seeds:
            seed.unfinished = _unfinished_training(tracker, seed.checkpoint_dir)
            if seed.unfinished is None:
                reused = _reusable_training(tracker, seed, parent_run_id)
                if reused is not None:
                    found[seed.key] = reused
                    continue
                if seed.job.force_retrain:
                    _clear_checkpoints(seed.checkpoint_dir)
            to_train.append(seed)
        if to_train:
            found.update(_train(to_train, tracker, parent_run_id, train_fn))
    return found[train_key(job)]


def tested_training(job: JobConfig, tracker: Tracker) -> Training | None:
    """A FINISHED training of the job's key whose test of this job has FINISHED too: the job has nothing
    left to do, so its network need not be on this machine. A network too large to carry between machines
    (the paper's image size) is then not trained again because it is gone. Only the newest training of the
    key counts, the one `obtain_training` would reuse; `force_retrain` asks for a new one, so it finds none."""
    if job.force_retrain:
        return None
    newest = next(iter(tracker.finished_trainings(train_key(job))), None)
    if newest is None or tracker.finished_evaluation(evaluation_key(job), newest.info.run_id) is None:
        return None
    return Training("reused", newest.info.run_id)


def training_lock(tracker: Tracker, key: str) -> tuple[FileLock, Path]:
    """The train_key's checkpoint folder and the lock its one trainer holds."""
    checkpoint_dir = tracker.location.checkpoint_root / key
    checkpoint_dir.mkdir(parents=True, exist_ok=True)
    return FileLock(str(checkpoint_dir / "train.lock")), checkpoint_dir


def group_lock(tracker: Tracker, job: JobConfig) -> FileLock:
    """The lock the job that trains `job`'s group holds while it locks the group's seeds and trains them."""
    folder = tracker.location.checkpoint_root / "groups"
    folder.mkdir(parents=True, exist_ok=True)
    return FileLock(str(folder / f"{group_id(job)}.lock"))


def _hold(held: ExitStack, lock: FileLock, waiting: str) -> None:
    if not _try_hold(held, lock):
        log.info(waiting)
        acquire_stoppably(lock, 1.0)
        held.callback(lock.release)


def _try_hold(held: ExitStack, lock: FileLock) -> bool:
    try:
        lock.acquire(timeout=0)
    except Timeout:
        return False
    held.callback(lock.release)
    return True


def _unfinished_training(tracker: Tracker, checkpoint_dir: Path) -> str | None:
    id_file = checkpoint_dir / RUN_ID_FILE
    if not id_file.exists():
        return None
    run = tracker.get_run(id_file.read_text().strip())
    if run is None or run.info.status == "FINISHED" or run.info.lifecycle_stage == "deleted":
        return None
    return run.info.run_id


def _reusable_training(tracker: Tracker, seed: _Seed, parent_run_id: str | None) -> Training | None:
    for run in tracker.finished_trainings(seed.key):
        # force_retrain means "not an older training": one trained earlier in this sweep counts.
        if seed.job.force_retrain and (parent_run_id is None or
                                       run.data.tags.get("mlflow.parentRunId") != parent_run_id):
            return None
        checkpoint = local_checkpoint(tracker, run, seed.checkpoint_dir)
        if checkpoint is not None:
            return Training("reused", run.info.run_id, checkpoint)
        log.warning("training run %s has no checkpoint left on disk or in the store", run.info.run_id)
    return None


def local_checkpoint(tracker: Tracker, run: Any, checkpoint_dir: Path) -> Path | None:
    """A training run's final checkpoint on this machine: where it was written, else fetched from the store."""
    saved = run.data.tags.get("checkpoint_path")
    if saved and Path(saved).is_file():
        return Path(saved)
    # Trained on another machine (remote store): fetch the logged artifact.
    try:
        fetched = tracker.download(run.info.run_id, CHECKPOINT_ARTIFACT, checkpoint_dir / "from_store")
    except Exception as error:
        log.debug("no checkpoint artifact in run %s: %s", run.info.run_id, error)
        return None
    if not fetched.is_dir():
        return fetched
    final = fetched / FINAL_CHECKPOINT
    return final if final.is_file() else None


def _clear_checkpoints(checkpoint_dir: Path) -> None:
    # The finished run keeps its checkpoint as an artifact; a forced retrain must not resume it.
    for path in checkpoint_dir.glob("*.pt"):
        path.unlink()
    (checkpoint_dir / RUN_ID_FILE).unlink(missing_ok=True)


def _train(seeds: list[_Seed], tracker: Tracker, parent_run_id: str | None,
           train_fn: TrainFn | None) -> dict[str, Training]:
    """Open each seed's run, train them (alone, or as one group), log what they made."""
    grouped = {"grouped": len(seeds), "trained_by_pid": os.getpid()} if len(seeds) > 1 else {}
    with ExitStack() as running:
        runs = []
        for seed in seeds:
            runs.append(_open_run(seed, tracker, {**run_tags(seed.job, seed.key), **grouped}, parent_run_id,
                                  running))
        first = seeds[0].job
        with tracker.system_metrics(runs[0][0], first.tracking.system_metrics):
            if len(seeds) == 1:
                if train_fn is None:
                    from ..learner import train as train_fn
                finals = [train_fn(first, seeds[0].checkpoint_dir, runs[0][2])]
            else:
                from ..learner import train_group

                log.info("grouped training of %d members of model '%s' (seeds %s)", len(seeds), first.model.name,
                         [seed.job.seed for seed in seeds])
                finals = train_group([s.job for s in seeds], [s.checkpoint_dir for s in seeds], [r[2] for r in runs])
        trained = {}
        for seed, (run_id, how, _), final in zip(seeds, runs, finals, strict=True):
            checkpoint = Path(final).resolve()
            _log_trained(seed.job, tracker, run_id, checkpoint)
            trained[seed.key] = Training(how, run_id, checkpoint)
    return trained


def _open_run(seed: _Seed, tracker: Tracker, tags: dict[str, Any], parent_run_id: str | None,
              running: ExitStack) -> tuple[str, str, LogFn]:
    """Start (or reopen, to resume) the seed's training run, ended by `running` (`run_status`) from the
    moment it is open; returns its id, how it trains, and the `log` callable the learner writes
    `train/*` curves through."""
    from ..models.builders import make_network
    from ..models.networks import param_counts

    job, checkpoint_dir = seed.job, seed.checkpoint_dir
    logged: dict[str, int] = {}
    if seed.unfinished is not None:
        run_id, how = seed.unfinished, "resumed"
        tracker.reopen(run_id)
        running.enter_context(run_status(tracker, run_id))
        resumes = int(tracker.get_run(run_id).data.tags.get("resumes", "0")) + 1
        tracker.set_tags(run_id, {"resumes": resumes, "device": job.device})
        # The killed attempt may have logged steps beyond its last checkpoint: keep those and log
        # only later steps, so that each step appears once (no store API deletes metric values).
        logged = tracker.logged_steps(run_id)
        log.info("resuming training run %s from %s", run_id, checkpoint_dir / LAST_CHECKPOINT)
    else:
        how = "trained"
        run_id = tracker.start_run(f"{job.model.name} seed{job.seed} training {seed.key}",
                                   {**tags, "stage": "train", "scenario": job.train_scenario.name}, parent_run_id,
                                   description=training_description(job, seed.key, checkpoint_dir))
        running.enter_context(run_status(tracker, run_id))
        _write_atomically(checkpoint_dir / RUN_ID_FILE, run_id)
    # Again on a resume: the killed attempt may have stopped before logging them (same values, allowed).
    tracker.log_params(run_id, {**flatten(training_config(job)),
                                **{k: str(v) for k, v in param_counts(make_network(job)).items()}})
    tracker.log_text(run_id, config_yaml(job), "config.yaml")

    def log_to_run(metrics: dict[str, float], step: int) -> None:
        new = {k: round(v, SCHEDULE_DECIMALS) if k in SCHEDULE_METRICS else v
               for k, v in metrics.items() if step > logged.get(k, -1)}
        if new:
            tracker.log_metrics(run_id, new, step)

    return run_id, how, log_to_run


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def _log_trained(job: JobConfig, tracker: Tracker, run_id: str, checkpoint: Path) -> None:
    """A finished training's artifacts: final.pt (and best.pt, ema.pt) as weights only, the MLflow model,
    the checkpoint's path. The optimiser and the replay memory stay in the local final.pt alone."""
    with tempfile.TemporaryDirectory() as tmp:
        for path in (checkpoint, checkpoint.with_name(BEST_CHECKPOINT), checkpoint.with_name(EMA_CHECKPOINT)):
            if path.is_file():
                tracker.log_artifact(run_id, weights_file(path, Path(tmp)), CHECKPOINT_ARTIFACT)
    if job.tracking.log_model:
        import torch

        from ..evaluation.policies import trained_network

        tracker.log_model(run_id, trained_network(job, checkpoint, torch.device("cpu")))
    tracker.set_tags(run_id, {"checkpoint_path": str(checkpoint)})


@contextmanager
def run_status(tracker: Tracker, run_id: str) -> Iterator[None]:
    """Ends the run FINISHED, or KILLED when the job was interrupted, or FAILED on any error."""
    try:
        yield
    except JobInterrupted:
        tracker.end(run_id, "KILLED")
        raise
    except BaseException:
        tracker.end(run_id, "FAILED")
        raise
    tracker.end(run_id, "FINISHED")


# --- which of a training's checkpoints a test drives ----------------------------------------------


def checkpoint_to_evaluate(job: JobConfig, training: Training) -> Path | None:
    """`eval.checkpoint`: the final network (the paper's protocol), the one with the best validation
    return, which training keeps as best.pt beside final.pt when validation is on, the moving average
    (ema.pt), or reselected.pt, which the test chooses among the kept validation passes' networks."""
    which = job.eval.checkpoint
    if training.checkpoint is None or which == "final":
        return training.checkpoint
    if which == "ema":
        ema = training.checkpoint.with_name(EMA_CHECKPOINT)
        if not ema.is_file():
            raise ConfigError(f"eval.checkpoint=ema, but the training (run {training.run_id}) kept no {EMA_CHECKPOINT} "
                              f"beside {training.checkpoint}: it trained with learner.ema_decay=0. Evaluate the final "
                              "network (eval.checkpoint=final), or train again with learner.ema_decay=0.999.")
        return ema
    if which == "reselected":
        kept = training.checkpoint.parent / VAL_CHECKPOINTS
        if not any(kept.glob("*.pt")):
            raise ConfigError(
                f"eval.checkpoint=reselected, but the training (run {training.run_id}) kept no validation pass's "
                f"network in {kept}: it trained with eval.keep_val_checkpoints=false. Test its best.pt "
                "(eval.checkpoint=best), or train again with eval.keep_val_checkpoints=true force_retrain=true.")
        return training.checkpoint.with_name(RESELECTED_CHECKPOINT)  # chosen when the test runs (reselection.py)
    if which == "safest":
        kept = training.checkpoint.parent / VAL_CHECKPOINTS
        if not any(kept.glob("*.pt")):
            raise ConfigError(
                f"eval.checkpoint=safest, but the training (run {training.run_id}) kept no validation pass's "
                f"network in {kept}: it trained with eval.keep_val_checkpoints=false. Test its best.pt "
                "(eval.checkpoint=best), or train again with eval.keep_val_checkpoints=true force_retrain=true.")
        return training.checkpoint.with_name(SAFEST_CHECKPOINT)  # chosen when the test runs (evaluation/safest.py)
    best = training.checkpoint.with_name(BEST_CHECKPOINT)
    if not best.is_file():
        raise ConfigError(
            f"eval.checkpoint=best, but the training (run {training.run_id}) kept no {BEST_CHECKPOINT} beside "
            f"{training.checkpoint}: it trained without validation (eval.val_every=0). Evaluate the final "
            "network (eval.checkpoint=final), or train again with validation "
            "(eval.val_every=N force_retrain=true).")
    if not chosen_by_current_validation(load_checkpoint(best)):
        raise ConfigError(
            f"eval.checkpoint=best, but {best} (run {training.run_id}) was chosen by the validation of before "
            f"evaluation version {EVALUATION_VERSION}, which handed hosts blank frames whenever another env restarted "
            "(hgm_repro.contracts.train_key). Test eval.checkpoint=final, or eval.checkpoint=reselected if the "
            "training kept its passes, or train again (force_retrain=true).")
    return best
