"""The sweep callback: one MLflow parent run per sweep, created before any job starts, the sweep's
shared values checked before anything is launched, and the plan of which seeds train together
(`runtime.grouped`) handed to the jobs. It trains nothing: each job gets its network from the
trainings service (`trainings.obtain_training`), which trains a planned group in its first job."""

from __future__ import annotations

import atexit
import json
import logging
import os
import re
import sys
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

from ..contracts.errors import BAD_INPUT_EXIT, ConfigError
from ..contracts.schema import check_config
from ..learner.grouped import use_grouped
from .descriptions import launch_description
from .provenance import launch_tags
from .store import CURVES_VIEW, PARENT_RUN_ENV, Tracker, resolve_location
from .trainings import TRAINING_GROUPS_ENV, plan_groups

log = logging.getLogger(__name__)


def _sweep_time(sweep_dir: Path) -> str:
    """`multirun/2026-12-02/22-11-36` -> `2026-12-02 22:11:36`: Hydra's default sweep directory
    names the time and its parent the date; another directory is named as it is."""
    date, time_of_day = sweep_dir.parent.name, sweep_dir.name
    if re.fullmatch(r"\d{4}-\d\d-\d\d", date) and re.fullmatch(r"\d\d-\d\d-\d\d", time_of_day):
        return f"{date} {time_of_day.replace('-', ':')}"
    return sweep_dir.name


def sweep_overrides(config: DictConfig) -> list[list[str]]:
    """The overrides of every job of a basic-sweeper sweep, in the sweeper's order (other sweepers
    choose their jobs as they go: none)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    if not str(config.hydra.sweeper.get("_target_", "")).endswith("BasicSweeper"):
        return []
    # The sweeper's own params (a grid config such as grid=paper) first: the command line's values
    # replace them, as in BasicSweeper.sweep.
    params = config.hydra.sweeper.get("params") or {}
    overrides = [f"{k}={v}" for k, v in params.items()]
    overrides += OmegaConf.to_container(config.hydra.overrides.task, resolve=False)
    batches = BasicSweeper.split_arguments(OverridesParser.create().parse_overrides(overrides), None)
    return [list(job) for batch in batches for job in batch]


def _sweep_jobs(config: DictConfig) -> list[Any]:
    """The validated config of every job of a basic-sweeper sweep. A job whose values do not
    validate is left out; it reports itself."""
    from hydra import compose

    jobs = []
    for job_overrides in sweep_overrides(config):
        try:
            cfg = compose(config_name=str(config.hydra.job.config_name), overrides=job_overrides)
            jobs.append(check_config(OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"])))
        except (ConfigError, ValueError, KeyError) as error:  # Hydra's own errors are ValueErrors too
            log.debug("job %s left to itself: %s", job_overrides, error)
    return jobs


def _hand_to_jobs(config: DictConfig, name: str, value: str) -> None:
    """Set environment variable `name` in every job of this sweep, wherever it runs.

    A worker of a Ray cluster started beforehand (`ray start`) does not inherit this process's
    environment. Every launcher builds each job's config from the sweep's Hydra overrides
    (`load_sweep_config`), and Hydra sets `hydra.job.env_set` in the job's process around the task,
    so an override added here (the callback runs before the sweeper and launcher are set up, on the
    same config) reaches the job on any node."""
    with open_dict(config.hydra), read_write(config.hydra):
        config.hydra.overrides.hydra.append(f"++hydra.job.env_set.{name}={value}")


class SweepTracking(Callback):
    """Hydra callback: one MLflow parent run per sweep, created before any job starts.

    Creating the store and the experiment here, in the launching process, means parallel
    jobs only ever open an existing store. Jobs find the parent run through an environment
    variable, which joblib's and submitit's workers inherit.
    """

    def __init__(self) -> None:
        self._tracker: Tracker | None = None
        self._parent: str | None = None
        self._description = ""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        # Values not swept over are the same in every job: a bad one stops the sweep here,
        # before the store or any job is touched. Swept values are checked by each job.
        # Hydra turns a callback's exception into a warning, so stop with SystemExit instead.
        try:
            check_config(OmegaConf.masked_copy(config, [k for k in config if k != "hydra"]))
        except ConfigError as error:
            print(f"hgm_repro: {error}\nnothing was launched.", file=sys.stderr)
            raise SystemExit(BAD_INPUT_EXIT) from error
        tracker = self._open(config)
        if tracker is None:
            return
        sweep_dir = str(config.hydra.sweep.dir)
        overrides = " ".join(OmegaConf.to_container(config.hydra.overrides.task, resolve=False))
        self._description = launch_description("sweep", overrides, Path(sweep_dir).resolve())
        self._parent = tracker.start_run(
            f"sweep {_sweep_time(Path(sweep_dir))}",
            {**launch_tags("sweep", overrides), "sweep_dir": str(Path(sweep_dir).resolve())},
            description=self._description,
        )
        os.environ[PARENT_RUN_ENV] = self._parent  # joblib's and submitit's workers inherit it
        _hand_to_jobs(config, PARENT_RUN_ENV, self._parent)
        # A sweep that raises never reaches on_multirun_end: close the parent run anyway.
        atexit.register(self._close, "FAILED")
        serve = tracker.ui_command()
        log.info("MLflow parent run %s (%s); evaluations: %s ; training curves: %s%s", self._parent,
                 tracker.location.tracking_uri, tracker.ui_url(), tracker.ui_url(CURVES_VIEW),
                 f" (serve the store first: {serve})" if serve else "")
        self._plan_training_groups(config)

    def _plan_training_groups(self, config: DictConfig) -> None:
        """Which seeds of the sweep train together, where `runtime.grouped` says so: handed to every job,
        whose trainings service trains a group in the group's first job (the others wait and reuse)."""
        task = [str(o) for o in OmegaConf.to_container(config.hydra.overrides.task, resolve=False)]
        # Expanding the sweep costs a compose per job: only when a job may group.
        deciders = ("runtime.grouped", "runtime", "device", "experiment")
        swept = any(o.split("=", 1)[0].lstrip("+~") in deciders for o in task)
        try:
            if not swept and not use_grouped(config.runtime.grouped, str(config.device)):
                log.info("runtime.grouped=%s on %s: each job trains its own model (solo)", config.runtime.grouped,
                         config.device)
                return
        except (ValueError, ConfigError):
            return  # a bad value: the jobs report it
        jobs = [job for job in _sweep_jobs(config) if job.model.learned]
        plan = plan_groups(jobs)
        if jobs:
            log.info("runtime.grouped=%s on %s: %s", jobs[0].runtime.grouped, jobs[0].device,
                     "training the seeds of each model together (a group's first job trains it)" if plan
                     else "each job trains its own model (solo)")
        if plan:
            text = json.dumps(plan, sort_keys=True)
            os.environ[TRAINING_GROUPS_ENV] = text  # joblib's and submitit's workers inherit it
            _hand_to_jobs(config, TRAINING_GROUPS_ENV, f"'{text}'")

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        if self._tracker is not None and self._parent is not None:
            try:
                self._tracker.summarise_launch(self._parent, self._description)
            except Exception as error:  # the summary is a convenience; the runs are all logged
                log.warning("sweep summary not logged: %s", error)
        self._close("FINISHED")
        atexit.unregister(self._close)

    def _open(self, config: DictConfig) -> Tracker | None:
        try:
            # HydraConfig is not set up yet in on_multirun_start: read the launch dir from the config.
            location = resolve_location(config.tracking, Path(config.hydra.runtime.cwd))
            self._tracker = Tracker(location, str(config.tracking.experiment_name))
        except Exception as error:  # the job reports a bad tracking config with context
            log.warning("tracking store not prepared before the jobs: %s", error)
            self._tracker = None
        return self._tracker

    def _close(self, status: str) -> None:
        if self._tracker is not None and self._parent is not None:
            self._tracker.end(self._parent, status)
            os.environ.pop(PARENT_RUN_ENV, None)
            os.environ.pop(TRAINING_GROUPS_ENV, None)
            self._parent = None
