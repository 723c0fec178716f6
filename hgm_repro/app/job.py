"""One job: check the config, get the trained network from the trainings service, evaluate it in the
test scenario, log it all.

`python -m hgm_repro` runs `hydra_job` once, a sweep (`-m`) once per job. The network comes from
`trainings.obtain_training` (reused, resumed or trained now; in a sweep that trains seeds together,
the first job of a group trains the group and the others find their seed finished); the test is
`evaluation.evaluate`, logged as one evaluation run beside the training run.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Mapping
from contextlib import nullcontext
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from ..contracts.checkpoint import RESELECTION_RECORD, SAFEST_RECORD, CheckpointMismatchError
from ..contracts.errors import BAD_INPUT_EXIT, ConfigError
from ..contracts.interrupts import JobInterrupted, hand_on, signals_raise
from ..contracts.names import VALIDATION_RETURN
from ..contracts.schema import JobConfig, check_config, results_model_name
from ..contracts.simulator_config import ScenarioConfig
from ..contracts.train_key import EVALUATION_VERSION, evaluation_key, train_key
from .descriptions import config_yaml, evaluation_description, launch_description, results_sentence
from .provenance import launch_tags, run_tags
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
from .trainings import (
    TRAINING_GROUPS_ENV,
    TrainFn,
    Training,
    checkpoint_to_evaluate,
    group_of,
    obtain_training,
    read_plan,
    run_status,
    tested_training,
)

log = logging.getLogger(__name__)

EvaluateFn = Callable[[JobConfig, ScenarioConfig, "Path | None"], Any]


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
    # Which seeds a sweep trains together: planned by the SweepTracking callback before the jobs start.
    groups = read_plan(os.environ.get(TRAINING_GROUPS_ENV)) if multirun else {}
    try:
        outcome = run_job(cfg, Path(get_original_cwd()), parent_run_id=parent, launch_overrides=single,
                          training_groups=groups)
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
    training_groups: Mapping[str, list[int]] | None = None,
) -> JobOutcome:
    """One job. `launch_overrides` (the command line's overrides) makes it a launch of its own:
    a parent run groups its training and evaluation, as a sweep's parent run groups a sweep's.
    `training_groups` (`trainings.plan_groups`) names the seeds a sweep trains together."""
    job = check_config(cfg)  # before anything touches the store, the disk or the simulator
    key = train_key(job)
    label = f"model={job.model.name} scenario={job.scenario.name} seed={job.seed} train_key={key}"
    log.info("job start: %s (preset=%s, device=%s)", label, job.experiment.name, job.device)
    started = time.monotonic()
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
            with run_status(tracker, launch_run) if launch_run else nullcontext():
                if job.model.learned:
                    members = group_of(job, training_groups or {})
                    training = (tested_training(job, tracker)
                                or obtain_training(members, tracker, parent_run_id, train_fn))
                    validation_return = tracker.best_value(training.run_id, VALIDATION_RETURN)
                else:
                    training = Training("none")
                eval_run_id, means = evaluate_and_log(job, tracker, parent_run_id, training, evaluate_fn)
                if launch_run:
                    tracker.summarise_launch(launch_run, description)
    except JobInterrupted as interrupted:
        log.error("job interrupted (%s): %s; the same command resumes it", interrupted, label)
        hand_on(interrupted)
    seconds = time.monotonic() - started
    summary = " ".join(f"{k}={v:.3g}" for k, v in means.items() if k in ("eval/avg_speed_kmh", "eval/episode_return"))
    log.info("job end: %s training=%s %s (%.1f s)", label, training.how, summary, seconds)
    return JobOutcome(key, training, eval_run_id, means, seconds, validation_return)


# --- evaluation ---------------------------------------------------------------------------


def evaluate_and_log(
    job: JobConfig, tracker: Tracker, parent_run_id: str | None, training: Training, evaluate_fn: EvaluateFn | None,
) -> tuple[str, dict[str, float]]:
    if evaluate_fn is None:
        from ..evaluation import evaluate as evaluate_fn
    checkpoint = checkpoint_to_evaluate(job, training)  # before the run: a missing best.pt is a config error
    key = evaluation_key(job)
    done = tracker.finished_evaluation(key, training.run_id)
    if done is not None:
        log.info("evaluation %s already finished in run %s: not repeated", key, done.info.run_id)
        return done.info.run_id, {k: v for k, v in done.data.metrics.items() if k.startswith("eval/")}
    safest_record = None
    if job.eval.checkpoint == "safest" and checkpoint is not None:
        from ..evaluation.safest import SafestRefused, choose_safest, outcome_tags

        # Chosen before the run opens: a training with no pass under the bar is refused with its message
        # and leaves no failed run in the store; the training run records the outcome either way.
        try:
            checkpoint, safest_record = choose_safest(job, checkpoint.parent)
        except SafestRefused as refused:
            if training.run_id:
                tracker.set_tags(training.run_id, outcome_tags(refused.record))
            raise
        if training.run_id:
            tracker.set_tags(training.run_id, outcome_tags(safest_record))
    eval_tags = {**run_tags(job, train_key(job)), "stage": "eval", "scenario": job.scenario.name,
                 "training": training.how, "evaluation_version": EVALUATION_VERSION, "evaluation_key": key}
    if training.run_id:
        eval_tags["train_run_id"] = training.run_id
    # A learned host tested under the layer it trained without is named so, never as the method.
    eval_tags["model"] = results_model_name(job)
    if checkpoint is not None:
        eval_tags["checkpoint"] = checkpoint.stem  # final, best, ema, reselected or safest
    name = f"{results_model_name(job)} seed{job.seed} {scenario_label(job.scenario.name)} eval"
    link = tracker.run_link(training.run_id, f"training run {training.run_id[:8]}") if training.run_id else None
    description = evaluation_description(job, training.how, link, checkpoint)
    run_id = tracker.start_run(name, eval_tags, parent_run_id, description=description)
    with run_status(tracker, run_id):
        tracker.log_params(run_id, flatten(job.resolved))
        tracker.log_text(run_id, config_yaml(job), "config.yaml")
        if job.eval.checkpoint == "reselected" and checkpoint is not None:
            from ..evaluation.reselection import reselect

            checkpoint, record = reselect(job, checkpoint.parent)
            tracker.log_text(run_id, json.dumps(record, indent=2), RESELECTION_RECORD)
            tracker.set_tags(run_id, {"reselected_env_steps": record["chosen_env_steps"]})
        if safest_record is not None:
            tracker.log_text(run_id, json.dumps(safest_record, indent=2), SAFEST_RECORD)
            tracker.set_tags(run_id, {"safest_env_steps": safest_record["chosen_env_steps"]})
        with tracker.system_metrics(run_id, job.tracking.system_metrics):
            result = evaluate_fn(job, job.scenario, checkpoint)
        means = {k: float(v) for k, v in result.means.items()}
        tracker.log_metrics(run_id, means, step=0)
        tracker.describe(run_id, description + "\n\n" + results_sentence(means))
        with tempfile.TemporaryDirectory() as tmp:
            episodes = Path(tmp) / "episodes.csv"
            plain_numbers(result.episodes).to_csv(episodes, index=False)
            tracker.log_artifact(run_id, episodes)
            if job.tracking.log_gif:
                _log_gif(job, checkpoint, tracker, run_id, Path(tmp))
    return run_id, means


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
