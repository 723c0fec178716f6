"""One job: validate the config, train once per `train_key`, evaluate in `cfg.scenario`, log it all.

Train once, evaluate many: training depends only on the training config (`train_key`), so a
sweep over test scenarios trains each model and seed once. The job that gets the key's file
lock in `checkpoints/<train_key>/` trains; the others wait on the lock, then find the FINISHED
training run in the store and only evaluate its checkpoint. The training run id is kept beside
the checkpoints, so a job killed mid-training and started again resumes the same MLflow run
from `last.pt` instead of opening a second one.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout
from omegaconf import DictConfig, OmegaConf

from .interrupts import JobInterrupted, raise_if_pending, sigterm_raises
from .schema import JobConfig, validate
from .tracking import PARENT_RUN_ENV, Tracker, flatten, git_info, resolve_location
from .train_key import train_key, training_config

log = logging.getLogger(__name__)

TrainFn = Callable[[DictConfig, Path, Callable[[dict[str, float], int], None]], Path]
EvaluateFn = Callable[[DictConfig, Any, "Path | None"], Any]
RUN_ID_FILE = "mlflow_run_id"  # beside the checkpoints: the training run a resume continues
CHECKPOINT_ARTIFACT = "checkpoint"


@dataclass
class Training:
    how: str  # "trained", "resumed", "reused", or "none" (non-learning driver)
    run_id: str | None = None
    checkpoint: Path | None = None


@dataclass
class JobOutcome:
    train_key: str
    training: Training
    eval_run_id: str
    means: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0


def hydra_job(cfg: DictConfig) -> float | None:
    """The body of `python -m hgm_repro`: Hydra's context turned into plain arguments."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from hydra.utils import get_original_cwd

    multirun = HydraConfig.get().mode == RunMode.MULTIRUN
    parent = os.environ.get(PARENT_RUN_ENV) if multirun else None
    outcome = run_job(cfg, Path(get_original_cwd()), parent_run_id=parent)
    return outcome.means.get("eval/episode_return")  # what a Hydra sweeper would optimise


def run_job(
    cfg: DictConfig,
    launch_dir: Path,
    parent_run_id: str | None = None,
    train_fn: TrainFn | None = None,
    evaluate_fn: EvaluateFn | None = None,
) -> JobOutcome:
    job = validate(cfg)  # before anything touches the store, the disk or the simulator
    key = train_key(cfg)
    label = f"model={job.model.name} scenario={job.scenario.name} seed={job.seed} train_key={key}"
    log.info("job start: %s (experiment=%s, device=%s)", label, job.experiment.name, job.device)
    started = time.monotonic()
    tracker = Tracker(resolve_location(cfg.tracking, launch_dir), job.tracking.experiment_name)
    for run_id in tracker.mark_orphans_killed(key):
        log.info("run %s was left RUNNING by a process that no longer exists: marked KILLED", run_id)
    commit, dirty = git_info()
    tags = {"model": job.model.name, "seed": job.seed, "train_key": key, "git_commit": commit,
            "git_dirty": dirty, "experiment": job.experiment.name, "device": job.device}
    try:
        with sigterm_raises():
            if job.model.learned:
                training = obtain_checkpoint(cfg, job, key, tracker, tags, parent_run_id, train_fn)
            else:
                training = Training("none")
            eval_run_id, means = evaluate_and_log(cfg, job, tracker, tags, parent_run_id, training, evaluate_fn)
    except JobInterrupted as interrupted:
        log.error("job interrupted (%s): %s; the same command resumes it", interrupted, label)
        raise SystemExit(128 + interrupted.signum) from interrupted
    seconds = time.monotonic() - started
    summary = " ".join(f"{k}={v:.3g}" for k, v in means.items() if k in ("eval/avg_speed_kmh", "eval/episode_return"))
    log.info("job end: %s training=%s %s (%.1f s)", label, training.how, summary, seconds)
    return JobOutcome(key, training, eval_run_id, means, seconds)


# --- training -----------------------------------------------------------------------------


def obtain_checkpoint(
    cfg: DictConfig, job: JobConfig, key: str, tracker: Tracker, tags: dict[str, Any],
    parent_run_id: str | None, train_fn: TrainFn | None,
) -> Training:
    """The key's finished checkpoint: from the store if there is one, else by training now."""
    checkpoint_dir = tracker.location.checkpoint_root / key
    checkpoint_dir.mkdir(parents=True, exist_ok=True)
    lock = FileLock(str(checkpoint_dir / "train.lock"))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        log.info("train_key=%s is being trained by another job: waiting for it", key)
        while True:  # in slices, so that a SIGTERM while waiting still stops the job
            try:
                lock.acquire(timeout=1.0)
                break
            except Timeout:
                raise_if_pending()
    try:
        unfinished = _unfinished_training(tracker, checkpoint_dir)
        if unfinished is None:
            reused = _reusable_training(tracker, key, job.force_retrain, parent_run_id, checkpoint_dir)
            if reused is not None:
                return reused
            if job.force_retrain:
                _clear_checkpoints(checkpoint_dir)
        return _train(cfg, key, tracker, tags, parent_run_id, train_fn, checkpoint_dir, unfinished)
    finally:
        lock.release()


def _unfinished_training(tracker: Tracker, checkpoint_dir: Path) -> str | None:
    """The run id of a training of this key that stopped before it finished (to resume)."""
    id_file = checkpoint_dir / RUN_ID_FILE
    if not id_file.exists():
        return None
    run = tracker.get_run(id_file.read_text().strip())
    if run is None or run.info.status == "FINISHED" or run.info.lifecycle_stage == "deleted":
        return None
    return run.info.run_id


def _reusable_training(
    tracker: Tracker, key: str, force_retrain: bool, parent_run_id: str | None, checkpoint_dir: Path
) -> Training | None:
    for run in tracker.finished_trainings(key):
        # force_retrain means "not an older training": one trained earlier in this sweep counts.
        if force_retrain and (parent_run_id is None or run.data.tags.get("mlflow.parentRunId") != parent_run_id):
            return None
        checkpoint = _local_checkpoint(tracker, run, checkpoint_dir)
        if checkpoint is not None:
            return Training("reused", run.info.run_id, checkpoint)
        log.warning("training run %s has no checkpoint left on disk or in the store", run.info.run_id)
    return None


def _local_checkpoint(tracker: Tracker, run: Any, checkpoint_dir: Path) -> Path | None:
    saved = run.data.tags.get("checkpoint_path")
    if saved and Path(saved).is_file():
        return Path(saved)
    # Trained on another machine (remote store): fetch the logged artifact.
    try:
        fetched = tracker.download(run.info.run_id, CHECKPOINT_ARTIFACT, checkpoint_dir / "from_store")
    except Exception as error:
        log.debug("no checkpoint artifact in run %s: %s", run.info.run_id, error)
        return None
    files = sorted(fetched.glob("*.pt")) if fetched.is_dir() else [fetched]
    return files[0] if files else None


def _clear_checkpoints(checkpoint_dir: Path) -> None:
    # The finished run keeps its checkpoint as an artifact; a forced retrain must not resume it.
    for path in checkpoint_dir.glob("*.pt"):
        path.unlink()
    (checkpoint_dir / RUN_ID_FILE).unlink(missing_ok=True)


def _train(
    cfg: DictConfig, key: str, tracker: Tracker, tags: dict[str, Any], parent_run_id: str | None,
    train_fn: TrainFn | None, checkpoint_dir: Path, unfinished: str | None,
) -> Training:
    if train_fn is None:
        from ..learner import train as train_fn
    job_tags = {**tags, "stage": "train", "scenario": str(cfg.train_scenario.name)}
    if unfinished is not None:
        run_id, how = unfinished, "resumed"
        tracker.reopen(run_id)
        resumes = int(tracker.get_run(run_id).data.tags.get("resumes", "0")) + 1
        tracker.set_tags(run_id, {"resumes": resumes, "device": tags["device"]})
        log.info("resuming training run %s from %s", run_id, checkpoint_dir / "last.pt")
    else:
        how = "trained"
        name = f"train-{cfg.model.name}-seed{cfg.seed}-{key}"
        run_id = tracker.start_run(name, job_tags, parent_run_id)
        (checkpoint_dir / RUN_ID_FILE).write_text(run_id)
        tracker.log_params(run_id, flatten(training_config(cfg)))
        tracker.log_text(run_id, OmegaConf.to_yaml(cfg, resolve=True), "config.yaml")

    def log_to_run(metrics: dict[str, float], step: int) -> None:
        tracker.log_metrics(run_id, metrics, step)

    with _run_status(tracker, run_id):
        checkpoint = Path(train_fn(cfg, checkpoint_dir, log_to_run)).resolve()
        tracker.log_artifact(run_id, checkpoint, CHECKPOINT_ARTIFACT)
        tracker.set_tags(run_id, {"checkpoint_path": str(checkpoint)})
    return Training(how, run_id, checkpoint)


@contextmanager
def _run_status(tracker: Tracker, run_id: str) -> Iterator[None]:
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


# --- evaluation ---------------------------------------------------------------------------


def evaluate_and_log(
    cfg: DictConfig, job: JobConfig, tracker: Tracker, tags: dict[str, Any], parent_run_id: str | None,
    training: Training, evaluate_fn: EvaluateFn | None,
) -> tuple[str, dict[str, float]]:
    if evaluate_fn is None:
        from ..evaluation import evaluate as evaluate_fn
    eval_tags = {**tags, "stage": "eval", "scenario": job.scenario.name, "training": training.how}
    if training.run_id:
        eval_tags["train_run_id"] = training.run_id
    name = f"eval-{job.model.name}-s{job.scenario.name}-seed{job.seed}"
    run_id = tracker.start_run(name, eval_tags, parent_run_id)
    with _run_status(tracker, run_id):
        tracker.log_params(run_id, flatten(cfg))
        tracker.log_text(run_id, OmegaConf.to_yaml(cfg, resolve=True), "config.yaml")
        result = evaluate_fn(cfg, cfg.scenario, training.checkpoint)
        means = {k: float(v) for k, v in result.means.items()}
        tracker.log_metrics(run_id, means, step=0)
        with tempfile.TemporaryDirectory() as tmp:
            episodes = Path(tmp) / "episodes.csv"
            result.episodes.to_csv(episodes, index_label="episode")
            tracker.log_artifact(run_id, episodes)
            if job.tracking.log_gif:
                _log_gif(cfg, training, tracker, run_id, Path(tmp))
    return run_id, means


def _log_gif(cfg: DictConfig, training: Training, tracker: Tracker, run_id: str, tmp: Path) -> None:
    """One evaluation episode as a GIF; optional, since a failed video must not fail a job."""
    from ..evaluation.media import record_gif

    path = tmp / "episode.gif"
    try:
        record_gif(cfg, training.checkpoint, path)
    except Exception as error:  # rendering is a nicety, the metrics are logged already
        log.warning("episode GIF failed: %s", error)
        tracker.set_tags(run_id, {"gif": f"failed: {str(error)[:200]}"})
        return
    tracker.log_artifact(run_id, path)
