"""One job: validate the config, train once per `train_key`, evaluate in the test scenario, log it all.

Train once, evaluate many: training depends only on the training config (`train_key`), so a
sweep over test scenarios trains each model and seed once. The job that gets the key's file
lock in `checkpoints/<train_key>/` trains; the others wait on the lock, then find the FINISHED
training run in the store and only evaluate its checkpoint. The training run id is kept beside
the checkpoints, so a job killed mid-training and started again resumes the same MLflow run
from `last.pt` instead of opening a second one.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout
from omegaconf import DictConfig, OmegaConf

from ..contracts.checkpoint import (
    BEST_CHECKPOINT,
    EMA_CHECKPOINT,
    FINAL_CHECKPOINT,
    LAST_CHECKPOINT,
    RESELECTED_CHECKPOINT,
    RESELECTION_RECORD,
    SAFEST_CHECKPOINT,
    SAFEST_RECORD,
    VAL_CHECKPOINTS,
    CheckpointMismatchError,
    chosen_by_current_validation,
    load_checkpoint,
    weights_file,
)
from ..contracts.errors import BAD_INPUT_EXIT, ConfigError
from ..contracts.interrupts import JobInterrupted, acquire_stoppably, hand_on, signals_raise
from ..contracts.names import VALIDATION_RETURN
from ..contracts.schema import JobConfig, results_model_name, validate
from ..contracts.simulator_config import ScenarioConfig
from ..contracts.train_key import EVALUATION_VERSION, evaluation_key, train_key, training_config
from .provenance import git_info, launch_description, launch_tags
from .store import (
    CURVES_VIEW,
    PARENT_RUN_ENV,
    StoreError,
    Tracker,
    flatten,
    resolve_location,
    scenario_label,
    tidy_number,
)

log = logging.getLogger(__name__)

TrainFn = Callable[[JobConfig, Path, Callable[[dict[str, float], int], None]], Path]
EvaluateFn = Callable[[JobConfig, ScenarioConfig, "Path | None"], Any]
RUN_ID_FILE = "mlflow_run_id"  # beside the checkpoints: the training run a resume continues
CHECKPOINT_ARTIFACT = "checkpoint"
# Linear schedules computed in float32 (epsilon 0.775002 for 0.775): their curves need 4 decimals.
SCHEDULE_METRICS = ("train/epsilon", "train/beta")
SCHEDULE_DECIMALS = 4


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
    validation_return: float | None = None  # the training run's best `val/episode_return`


def hydra_job(cfg: DictConfig) -> float | None:
    """The body of `python -m hgm_repro`: Hydra's context turned into plain arguments."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from hydra.utils import get_original_cwd

    # TorchRL announces every replay storage it makes at INFO: noise in a job's log. It sets its
    # logger's level from RL_LOGGING_LEVEL when first imported, which may be later than this.
    os.environ.setdefault("RL_LOGGING_LEVEL", "WARNING")
    logging.getLogger("torchrl").setLevel(os.environ["RL_LOGGING_LEVEL"])
    hydra_cfg = HydraConfig.get()
    multirun = hydra_cfg.mode == RunMode.MULTIRUN
    # A sweep's parent run is opened by the SweepTracking callback; a single job opens its own.
    parent = os.environ.get(PARENT_RUN_ENV) if multirun else None
    single = None if multirun else " ".join(hydra_cfg.overrides.task)
    try:
        outcome = run_job(cfg, Path(get_original_cwd()), parent_run_id=parent, launch_overrides=single)
    except (ConfigError, StoreError, CheckpointMismatchError) as error:
        print(f"hgm_repro: {error}", file=sys.stderr)
        raise SystemExit(BAD_INPUT_EXIT) from error
    if os.environ.get("SLURM_JOB_ID"):
        # The job's work is done and recorded. A SLURM task runs one job, so the time-limit signal
        # (USR2, sent `signal_delay_s` early) can now only come while submitit writes the result or
        # Python exits: requeueing would repeat a finished job, and a USR2 after submitit's own
        # handling ends kills the process, so that SLURM marks a finished job FAILED (CI saw both
        # tasks of an array FAILED on signal 12 a second after "Job completed successfully").
        signal.signal(signal.SIGUSR2, signal.SIG_IGN)
    # What a Hydra sweeper optimises: the validation return, never a test scenario's.
    if multirun and outcome.validation_return is None and outcome.training.how != "none":
        log.warning("no %s in training run %s (validation off: eval.val_every=0): a sweeper gets "
                    "nothing to optimise", VALIDATION_RETURN, outcome.training.run_id)
    return outcome.validation_return


def run_job(
    cfg: DictConfig,
    launch_dir: Path,
    parent_run_id: str | None = None,
    train_fn: TrainFn | None = None,
    evaluate_fn: EvaluateFn | None = None,
    launch_overrides: str | None = None,
) -> JobOutcome:
    """One job. `launch_overrides` (the command line's overrides) makes it a launch of its own:
    a parent run groups its training and evaluation, as a sweep's parent run groups a sweep's."""
    job = validate(cfg)  # before anything touches the store, the disk or the simulator
    key = train_key(job)
    label = f"model={job.model.name} scenario={job.scenario.name} seed={job.seed} train_key={key}"
    log.info("job start: %s (experiment=%s, device=%s)", label, job.experiment.name, job.device)
    started = time.monotonic()
    commit, dirty = git_info()
    tags = {"model": job.model.name, "seed": job.seed, "train_key": key, "git_commit": commit,
            "git_dirty": dirty, "experiment": job.experiment.name, "device": job.device}
    launch_run = description = None
    validation_return = None
    try:
        with signals_raise():
            tracker = Tracker(resolve_location(asdict(job.tracking), launch_dir), job.tracking.experiment_name)
            for run_id in tracker.close_orphans():
                log.info("run %s was left RUNNING by a process that no longer exists: marked KILLED", run_id)
            serve = tracker.ui_command()
            # A sweep says it once, when it starts (`SweepTracking`); a single job here.
            level = logging.INFO if parent_run_id is None else logging.DEBUG
            log.log(level, "MLflow runs: %s ; training curves: %s%s", tracker.ui_url(), tracker.ui_url(CURVES_VIEW),
                    f" (serve the store first: {serve})" if serve else "")
            if launch_overrides is not None and parent_run_id is None:
                description = launch_description("job", launch_overrides, Path(launch_dir).resolve())
                launch_run = parent_run_id = tracker.start_run(
                    f"job {job.model.name} seed{job.seed} {scenario_label(job.scenario.name)}",
                    {**launch_tags("job", launch_overrides), "train_key": key}, description=description)
            with _run_status(tracker, launch_run) if launch_run else nullcontext():
                if job.model.learned:
                    training = obtain_checkpoint(job, key, tracker, tags, parent_run_id, train_fn)
                    validation_return = tracker.best_value(training.run_id, VALIDATION_RETURN)
                else:
                    training = Training("none")
                eval_run_id, means = evaluate_and_log(job, tracker, tags, parent_run_id, training, evaluate_fn)
                if launch_run:
                    tracker.summarise_launch(launch_run, description)
    except JobInterrupted as interrupted:
        log.error("job interrupted (%s): %s; the same command resumes it", interrupted, label)
        hand_on(interrupted)
    seconds = time.monotonic() - started
    summary = " ".join(f"{k}={v:.3g}" for k, v in means.items() if k in ("eval/avg_speed_kmh", "eval/episode_return"))
    log.info("job end: %s training=%s %s (%.1f s)", label, training.how, summary, seconds)
    return JobOutcome(key, training, eval_run_id, means, seconds, validation_return)


# --- training -----------------------------------------------------------------------------


def training_lock(tracker: Tracker, key: str) -> tuple[FileLock, Path]:
    """The train_key's checkpoint folder and the lock its one trainer holds (jobs and groups alike)."""
    checkpoint_dir = tracker.location.checkpoint_root / key
    checkpoint_dir.mkdir(parents=True, exist_ok=True)
    return FileLock(str(checkpoint_dir / "train.lock")), checkpoint_dir


def obtain_checkpoint(
    job: JobConfig, key: str, tracker: Tracker, tags: dict[str, Any],
    parent_run_id: str | None, train_fn: TrainFn | None,
) -> Training:
    """The key's finished checkpoint: from the store if there is one, else by training now."""
    lock, checkpoint_dir = training_lock(tracker, key)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        log.info("train_key=%s is being trained by another job: waiting for it", key)
        acquire_stoppably(lock, 1.0)
    try:
        unfinished = _unfinished_training(tracker, checkpoint_dir)
        if unfinished is None:
            reused = _reusable_training(tracker, key, job.force_retrain, parent_run_id, checkpoint_dir)
            if reused is not None:
                return reused
            if job.force_retrain:
                _clear_checkpoints(checkpoint_dir)
        return _train(job, key, tracker, tags, parent_run_id, train_fn, checkpoint_dir, unfinished)
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
        checkpoint = local_checkpoint(tracker, run, checkpoint_dir)
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


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def _clear_checkpoints(checkpoint_dir: Path) -> None:
    # The finished run keeps its checkpoint as an artifact; a forced retrain must not resume it.
    for path in checkpoint_dir.glob("*.pt"):
        path.unlink()
    (checkpoint_dir / RUN_ID_FILE).unlink(missing_ok=True)


def _train(
    job: JobConfig, key: str, tracker: Tracker, tags: dict[str, Any], parent_run_id: str | None,
    train_fn: TrainFn | None, checkpoint_dir: Path, unfinished: str | None,
) -> Training:
    if train_fn is None:
        from ..learner import train as train_fn

    run_id, how, log_to_run = _open_training(job, key, tracker, tags, parent_run_id, checkpoint_dir, unfinished)
    with _run_status(tracker, run_id):
        with tracker.system_metrics(run_id, job.tracking.system_metrics):
            checkpoint = Path(train_fn(job, checkpoint_dir, log_to_run)).resolve()
        _log_trained(job, tracker, run_id, checkpoint)
    return Training(how, run_id, checkpoint)


def _open_training(
    job: JobConfig, key: str, tracker: Tracker, tags: dict[str, Any], parent_run_id: str | None,
    checkpoint_dir: Path, unfinished: str | None,
) -> tuple[str, str, Callable[[dict[str, float], int], None]]:
    """Start (or reopen, to resume) the key's training run; returns its id, how it trains, and the
    `log` callable the learner writes `train/*` curves through."""
    from ..models.builders import make_network
    from ..models.networks import param_counts

    job_tags = {**tags, "stage": "train", "scenario": job.train_scenario.name}
    logged: dict[str, int] = {}
    if unfinished is not None:
        run_id, how = unfinished, "resumed"
        tracker.reopen(run_id)
        resumes = int(tracker.get_run(run_id).data.tags.get("resumes", "0")) + 1
        tracker.set_tags(run_id, {"resumes": resumes, "device": tags["device"]})
        # The killed attempt may have logged steps beyond its last checkpoint: keep those and log
        # only later steps, so that each step appears once (no store API deletes metric values).
        logged = tracker.logged_steps(run_id)
        log.info("resuming training run %s from %s", run_id, checkpoint_dir / LAST_CHECKPOINT)
    else:
        how = "trained"
        run_id = tracker.start_run(f"{job.model.name} seed{job.seed} training {key}", job_tags, parent_run_id,
                                   description=_training_description(job, key, checkpoint_dir))
        _write_atomically(checkpoint_dir / RUN_ID_FILE, run_id)
    # Again on a resume: the killed attempt may have stopped before logging them (same values, allowed).
    tracker.log_params(run_id, {**flatten(training_config(job)),
                                **{k: str(v) for k, v in param_counts(make_network(job)).items()}})
    tracker.log_text(run_id, _config_yaml(job), "config.yaml")

    def log_to_run(metrics: dict[str, float], step: int) -> None:
        new = {k: round(v, SCHEDULE_DECIMALS) if k in SCHEDULE_METRICS else v
               for k, v in metrics.items() if step > logged.get(k, -1)}
        if new:
            tracker.log_metrics(run_id, new, step)

    return run_id, how, log_to_run


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


def train_grouped(jobs: list[JobConfig], tracker: Tracker, parent_run_id: str | None) -> list[str]:
    """Train the jobs' distinct, not yet finished trainings in groups (`hgm_repro.learner.grouped`):
    each member is its own training run under `parent_run_id`, exactly as a job's solo training
    would be, so that the jobs afterwards find them FINISHED and only evaluate. Returns the
    train_keys trained. A key another process holds the lock of is left to the jobs."""
    from contextlib import ExitStack

    from ..learner import train_group
    from ..learner.grouped import group_key

    commit, dirty = git_info()
    groups: dict[str, list[JobConfig]] = {}
    seen: set[str] = set()
    for job in jobs:
        key = train_key(job)
        if not job.model.learned or key in seen or job.force_retrain or tracker.finished_trainings(key):
            continue
        seen.add(key)
        groups.setdefault(group_key(job), []).append(job)
    trained: list[str] = []
    for members in groups.values():
        with ExitStack() as stack:
            ready, opened = [], []
            for job in members:
                key = train_key(job)
                lock, checkpoint_dir = training_lock(tracker, key)
                try:
                    lock.acquire(timeout=0)
                except Timeout:
                    continue  # another process trains it; its jobs wait for that one
                stack.callback(lock.release)
                ready.append((job, key, checkpoint_dir))
            if len(ready) < 2:
                continue  # nothing to group: the jobs train it solo
            for job, key, checkpoint_dir in ready:
                tags = {"model": job.model.name, "seed": job.seed, "train_key": key, "git_commit": commit,
                        "git_dirty": dirty, "experiment": job.experiment.name, "device": job.device,
                        "grouped": len(ready), "trained_by_pid": os.getpid()}
                unfinished = _unfinished_training(tracker, checkpoint_dir)
                run_id, _, log_to_run = _open_training(job, key, tracker, tags, parent_run_id, checkpoint_dir,
                                                       unfinished)
                stack.enter_context(_run_status(tracker, run_id))  # KILLED / FAILED / FINISHED, as solo
                opened.append((run_id, log_to_run))
            log.info("grouped training of %d members of model '%s' (seeds %s)", len(ready),
                     ready[0][0].model.name, [job.seed for job, _, _ in ready])
            finals = train_group([job for job, _, _ in ready], [d for _, _, d in ready], [lg for _, lg in opened])
            for (job, key, _), (run_id, _), final in zip(ready, opened, finals, strict=True):
                _log_trained(job, tracker, run_id, Path(final).resolve())
                trained.append(key)
    return trained


def _training_description(job: JobConfig, key: str, checkpoint_dir: Path) -> str:
    return (f"Training of **{job.model.name}** (seed {job.seed}) in the training traffic "
            f"(`{job.train_scenario.name}`) for {job.learner.total_steps} env steps, experiment preset "
            f"`{job.experiment.name}`, train_key `{key}`. Checkpoints in `{checkpoint_dir}`; the final network "
            "is also the MLflow model `model` of this run (`mlflow.pytorch.load_model`). Every evaluation of "
            "this training links here.")


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
    job: JobConfig, tracker: Tracker, tags: dict[str, Any], parent_run_id: str | None,
    training: Training, evaluate_fn: EvaluateFn | None,
) -> tuple[str, dict[str, float]]:
    if evaluate_fn is None:
        from ..evaluation import evaluate as evaluate_fn
    checkpoint = checkpoint_to_evaluate(job, training)  # before the run: a missing best.pt is a config error
    key = evaluation_key(job)
    done = tracker.finished_evaluation(key, training.run_id)
    if done is not None:
        log.info("evaluation %s already finished in run %s: not repeated", key, done.info.run_id)
        return done.info.run_id, {k: v for k, v in done.data.metrics.items() if k.startswith("eval/")}
    eval_tags = {**tags, "stage": "eval", "scenario": job.scenario.name, "training": training.how,
                 "evaluation_version": EVALUATION_VERSION,
                 "evaluation_key": key}
    if training.run_id:
        eval_tags["train_run_id"] = training.run_id
    # A learned host tested under the layer it trained without is named so, never as the method.
    eval_tags["model"] = results_model_name(job)
    if checkpoint is not None:
        eval_tags["checkpoint"] = checkpoint.stem  # final or best
    name = f"{results_model_name(job)} seed{job.seed} {scenario_label(job.scenario.name)} eval"
    description = _evaluation_description(job, tracker, training, checkpoint)
    run_id = tracker.start_run(name, eval_tags, parent_run_id, description=description)
    with _run_status(tracker, run_id):
        tracker.log_params(run_id, flatten(job.resolved))
        tracker.log_text(run_id, _config_yaml(job), "config.yaml")
        if job.eval.checkpoint == "reselected" and checkpoint is not None:
            from ..evaluation.reselection import reselect

            checkpoint, record = reselect(job, checkpoint.parent)
            tracker.log_text(run_id, json.dumps(record, indent=2), RESELECTION_RECORD)
            tracker.set_tags(run_id, {"reselected_env_steps": record["chosen_env_steps"]})
        if job.eval.checkpoint == "safest" and checkpoint is not None:
            from ..evaluation.safest import choose_safest

            checkpoint, record = choose_safest(job, checkpoint.parent)
            tracker.log_text(run_id, json.dumps(record, indent=2), SAFEST_RECORD)
            tracker.set_tags(run_id, {"safest_env_steps": record["chosen_env_steps"]})
        with tracker.system_metrics(run_id, job.tracking.system_metrics):
            result = evaluate_fn(job, job.scenario, checkpoint)
        means = {k: float(v) for k, v in result.means.items()}
        tracker.log_metrics(run_id, means, step=0)
        tracker.describe(run_id, description + "\n\n" + _results_sentence(means))
        with tempfile.TemporaryDirectory() as tmp:
            episodes = Path(tmp) / "episodes.csv"
            plain_numbers(result.episodes).to_csv(episodes, index=False)
            tracker.log_artifact(run_id, episodes)
            if job.tracking.log_gif:
                _log_gif(job, checkpoint, tracker, run_id, Path(tmp))
    return run_id, means


def _evaluation_description(job: JobConfig, tracker: Tracker, training: Training, checkpoint: Path | None) -> str:
    scenario = job.scenario.name
    where = f"scenario {scenario}" if str(scenario).isdigit() else f"the `{scenario}` traffic"
    text = (f"Evaluation of **{job.model.name}** (seed {job.seed}) in {where}: {job.eval.test_steps} greedy "
            f"decisions over {job.eval.test_envs} envs, test traffic drawn from seeds no training uses.")
    if training.run_id is None:
        return text + " A non-learning host: nothing was trained."
    link = tracker.run_link(training.run_id, f"training run {training.run_id[:8]}")
    how = {"reused": "reused from", "trained": "trained by", "resumed": "resumed by"}.get(training.how, "from")
    return text + f" The network ({checkpoint.name if checkpoint else '?'}) was {how} {link}."


def _results_sentence(means: dict[str, float]) -> str:
    parts = [f"{label} **{means[key]:.4g}**" for key, label in (
        ("eval/episode_return", "mean episode return"), ("eval/avg_speed_kmh", "speed (km/h)"),
        ("eval/collisions", "collisions per episode"), ("eval/episodes", "episodes")) if key in means]
    return "Results: " + ", ".join(parts) + "." if parts else ""


def plain_numbers(frame: Any) -> Any:
    """A table as people read it: counts as integers, other values without float32 tails
    (75.400024 -> 75.4), as the logged metrics (`tidy_number`)."""
    out = frame.copy()
    for column in out.columns:
        values = out[column]
        if values.dtype.kind != "f":
            continue
        finite = values.dropna()
        if len(finite) == len(values) and (finite == finite.round()).all():
            out[column] = values.astype("int64")
        else:
            out[column] = values.map(tidy_number)
    return out


def _config_yaml(job: JobConfig) -> str:
    """The resolved config as a run's `config.yaml`."""
    return OmegaConf.to_yaml(OmegaConf.create(job.resolved))


def _log_gif(job: JobConfig, checkpoint: Path | None, tracker: Tracker, run_id: str, tmp: Path) -> None:
    """One evaluation episode as a GIF; optional, since a failed video must not fail a job."""
    from ..evaluation.media import record_gif

    path = tmp / "episode.gif"
    try:
        record_gif(job, checkpoint, path)
    except Exception as error:  # rendering is a nicety, the metrics are logged already
        log.warning("episode GIF failed: %s", error)
        tracker.set_tags(run_id, {"gif": f"failed: {str(error)[:200]}"})
        return
    tracker.log_artifact(run_id, path)
