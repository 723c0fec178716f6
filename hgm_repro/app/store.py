"""The MLflow store: where it is, how runs are opened, tagged, logged and closed.

Every call goes through `MlflowClient` (no fluent, process-global active run), because one
process may hold a sweep's parent run, a training run and an evaluation run at once.
The default store is a SQLite file that parallel jobs share, so store creation happens under
a file lock and every write is retried while SQLite answers "database is locked".

A run is RUNNING in the store while a process works on it, and that process holds the run's
lock file (`<launch dir>/.mlflow_run_locks/<run id>.lock`) until it closes the run. A job that
opens the store closes every RUNNING run whose lock nobody holds (its process was SIGKILLed,
or its machine lost power) as KILLED; the operating system drops a dead process's locks.
"""

from __future__ import annotations

import json
import logging
import math
import os
import socket
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from filelock import FileLock, Timeout
from omegaconf import DictConfig

from ..contracts.config_tree import flatten as flatten_tree
from ..contracts.interrupts import acquire_stoppably, deferred, protected
from .descriptions import EXPERIMENT_DESCRIPTION
from .provenance import source_tags

log = logging.getLogger(__name__)
T = TypeVar("T")

# MLflow's limits, the older (stricter) server values so that any server accepts our batches.
MAX_PARAM_VALUE = 500
PARAMS_PER_BATCH = 100
METRICS_PER_BATCH = 1000
PARENT_RUN_ENV = "HGM_REPRO_PARENT_RUN_ID"  # how a sweep's parent run id reaches its jobs
# MLflow's own tags: the UI shows them as a run's Source, Version and User, and its description.
NOTE = "mlflow.note.content"
# MLflow 3 opens an experiment on its GenAI pages unless told otherwise.
RUNS_VIEW = "runs?workflowType=machine_learning"
# Views of the runs page that a link opens (`viewStateShareKey=<key>`) and the UI's Views menu
# lists: MLflow 3 reads them from the experiment's tags `mlflow.sharedViewState.<key>`, each an
# envelope {name, createdAt, updatedAt, state} whose state is the JSON of its search facets and
# table state (what the UI's own "Save as new view" writes). A search filter with a sort other
# than the start time lists matching runs flat instead of folded under their launch.
SHARED_VIEW_TAG = "mlflow.sharedViewState."
GRID_VIEW, CURVES_VIEW = "grid", "curves"
_GRID_COLUMNS = ("tags.`model`", "tags.`scenario`", "tags.`seed`", "metrics.`eval/episode_return`",
                 "metrics.`eval/collisions`", "metrics.`eval/avg_speed_kmh`")
VIEW_NAMES = {"grid": "Evaluations grid", "curves": "Training curves"}
SHARED_VIEWS: dict[str, dict[str, Any]] = {
    # Every evaluation a row: model, scenario, seed and its results readable without a click.
    GRID_VIEW: {"searchFilter": "tags.stage = 'eval'", "orderByKey": "tags.`scenario`", "orderByAsc": True,
                "selectedColumns": list(_GRID_COLUMNS),
                "columnOrder": ["attributes.`Run Name`", *_GRID_COLUMNS],
                "columnWidths": {"attributes.`Run Name`": 230, "tags.`model`": 90, "tags.`scenario`": 80,
                                 "tags.`seed`": 60, "metrics.`eval/episode_return`": 160,
                                 "metrics.`eval/collisions`": 130, "metrics.`eval/avg_speed_kmh`": 170}},
    # The training runs, for the chart view: their train/ and val/ curves.
    CURVES_VIEW: {"searchFilter": "tags.stage = 'train'", "orderByKey": "tags.`model`", "orderByAsc": True,
                  "selectedColumns": ["tags.`model`", "tags.`seed`", "metrics.`val/best_episode_return`"],
                  "hideEmptyCharts": True},
}
# What a launch's parent run summarises of its evaluations (means over seeds).
SUMMARY_METRICS = ("episode_return", "avg_speed_kmh", "collisions")
# What this version of hgm_repro writes into an experiment (tags and names); another value on
# an existing experiment means another version made it.
STORE_FORMAT = "1"
STORE_FORMAT_TAG = "hgm_repro.store_format"


class StoreError(RuntimeError):
    """The tracking store cannot be used by this version (another MLflow schema or hgm_repro format)."""


@dataclass(frozen=True)
class StoreLocation:
    """Where runs, artifacts and checkpoints of this launch go (all absolute)."""

    tracking_uri: str
    artifact_location: str | None  # None: the server decides (remote stores)
    checkpoint_root: Path
    lock_path: Path  # serialises store and experiment creation between processes

    @property
    def run_locks(self) -> Path:
        """Where the processes that run the store's RUNNING runs hold their lock files."""
        return self.lock_path.parent / ".mlflow_run_locks"

    @property
    def is_local(self) -> bool:
        return self.tracking_uri.startswith("sqlite:") or self.tracking_uri.startswith("file:")


def resolve_location(tracking: Mapping[str, Any] | DictConfig, launch_dir: Path, create: bool = True) -> StoreLocation:
    """Make `tracking.*` absolute against the directory the command was started from. A SQLite store named by
    `tracking.uri` is kept like the default one: artifacts beside it, and its directory made (with `create`;
    a reader passes False) and logged when missing."""
    launch_dir = Path(launch_dir).resolve()

    def under_launch(value: str | None, default: str) -> Path:
        return (launch_dir / (value or default)).resolve()  # an absolute value replaces launch_dir

    uri = tracking.get("uri")
    checkpoint_root = under_launch(tracking.get("checkpoint_dir"), "checkpoints")
    if uri and str(uri).startswith("sqlite:///"):
        db = under_launch(str(uri).removeprefix("sqlite:///"), "mlflow.db")
        if create and not db.parent.is_dir():
            log.warning("tracking.uri=%s: creating the missing directory %s for the store", uri, db.parent)
            db.parent.mkdir(parents=True, exist_ok=True)
        artifact_dir = tracking.get("artifact_dir")
        artifacts = under_launch(artifact_dir, "") if artifact_dir else db.parent / "mlartifacts"
        return StoreLocation(f"sqlite:///{db}", artifacts.as_uri(), checkpoint_root, db.with_name(f"{db.name}.lock"))
    if uri:
        return StoreLocation(str(uri), None, checkpoint_root, checkpoint_root.parent / ".mlflow_store.lock")
    db = launch_dir / "mlflow.db"
    artifacts = under_launch(tracking.get("artifact_dir"), "mlartifacts")
    return StoreLocation(f"sqlite:///{db}", artifacts.as_uri(), checkpoint_root, launch_dir / "mlflow.db.lock")


def _is_transient(error: Exception) -> bool:
    text = str(error).lower()
    return "database is locked" in text or "database is busy" in text or "unable to open database" in text


def retry(call: Callable[..., T], *args: Any, attempts: int = 12, **kwargs: Any) -> T:
    """Run one store call, retrying with backoff while SQLite is locked by another writer."""
    for attempt in range(attempts):
        try:
            return call(*args, **kwargs)
        except Exception as error:  # MlflowException or sqlalchemy's OperationalError
            if attempt == attempts - 1 or not _is_transient(error):
                raise
            time.sleep(min(0.2 * 2**attempt, 5.0))
    raise AssertionError("unreachable")


def tidy_number(value: Any) -> float:
    """A metric value as a python float without float32 noise: whole numbers stay exact, others keep
    6 significant digits (a float32 mean of speeds gives 59.999992 for 60)."""
    number = float(value)
    if not math.isfinite(number) or number.is_integer():
        return number
    return float(f"{number:.6g}")


def scenario_label(name: str) -> str:
    """`3` -> `scenario3`, `train` -> `train-traffic`: never a bare `s3`, which reads as `strain` for `train`."""
    return f"scenario{name}" if str(name).isdigit() else f"{name}-traffic"


def flatten(node: Mapping[str, Any] | DictConfig, prefix: str = "") -> dict[str, str]:
    """`{'a': {'b': 1}}` -> `{'a.b': '1'}`, values cut to MLflow's param length."""
    return {k: str(v)[:MAX_PARAM_VALUE] for k, v in flatten_tree(node, prefix).items()}


def _chunks(items: list[T], size: int) -> Iterable[list[T]]:
    for start in range(0, len(items), size):
        yield items[start : start + size]


class Tracker:
    """One experiment in one store; all writes retried and shielded from stop signals mid-write."""

    def __init__(self, location: StoreLocation, experiment_name: str) -> None:
        from mlflow.tracking import MlflowClient

        self.location = location
        # Creating a SQLite store runs its schema migrations: two processes doing that at
        # once corrupt it, so the first touch of the store and the experiment is locked.
        location.lock_path.parent.mkdir(parents=True, exist_ok=True)
        self._held: dict[str, FileLock] = {}  # run id -> the lock that says this process runs it
        with FileLock(str(location.lock_path)):
            try:
                _create_sqlite_store_atomically(location.tracking_uri)
                self.client = MlflowClient(tracking_uri=location.tracking_uri)
                experiment = retry(self._get_or_create_experiment, experiment_name)
            except Exception as error:
                raise StoreError(_store_problem(location.tracking_uri, error)) from error
        found = experiment.tags.get(STORE_FORMAT_TAG)
        if found is not None and found != STORE_FORMAT:
            raise StoreError(
                f"experiment '{experiment_name}' in the MLflow store {location.tracking_uri} was written by another "
                f"version of hgm_repro (store format {found}; this version writes format {STORE_FORMAT}). "
                f"Use another tracking.experiment_name or tracking.uri, or the hgm_repro version that wrote it.")
        if found is None:
            retry(self.client.set_experiment_tag, experiment.experiment_id, STORE_FORMAT_TAG, STORE_FORMAT)
        self.experiment_id = experiment.experiment_id
        retry(self._describe_experiment)

    def _describe_experiment(self) -> None:
        """The experiment's description, and its kind, so that the UI opens on runs (not GenAI traces)."""
        tags = self.client.get_experiment(self.experiment_id).tags
        wanted = {NOTE: EXPERIMENT_DESCRIPTION, "mlflow.experimentKind": "custom_model_development",
                  **{SHARED_VIEW_TAG + key: shared_view(key) for key in SHARED_VIEWS}}
        for key, value in wanted.items():
            if key not in tags:  # never overwrite what a user wrote in the UI
                self.client.set_experiment_tag(self.experiment_id, key, value)

    def ui_url(self, view: str = GRID_VIEW) -> str:
        """The address that opens this experiment's runs in the MLflow UI (`mlflow ui` for a local
        store) on one of `SHARED_VIEWS`: the evaluations as a table, or the training curves as charts."""
        uri = self.location.tracking_uri
        base = uri.rstrip("/") if uri.startswith(("http://", "https://")) else "http://127.0.0.1:5000"
        mode = "&compareRunsMode=CHART" if view == CURVES_VIEW else ""
        return f"{base}/#/experiments/{self.experiment_id}/{RUNS_VIEW}{mode}&viewStateShareKey={view}"

    def ui_command(self) -> str | None:
        """The `mlflow ui` command that serves a local store (None for a server)."""
        if not self.location.is_local:
            return None
        root = self.location.artifact_location
        artifacts = f" --default-artifact-root {root}" if root else ""
        return f"mlflow ui --backend-store-uri {self.location.tracking_uri}{artifacts}"

    def run_link(self, run_id: str, text: str) -> str:
        """A markdown link to a run that works inside the UI (descriptions are rendered there)."""
        return f"[{text}](#/experiments/{self.experiment_id}/runs/{run_id}?workflowType=machine_learning)"

    def __getstate__(self) -> dict[str, Any]:
        # submitit pickles Hydra's callbacks with each job: run locks belong to this process only.
        return {**self.__dict__, "_held": {}}

    def _get_or_create_experiment(self, name: str) -> Any:
        found = self.client.get_experiment_by_name(name)
        if found is not None:
            if found.lifecycle_stage == "deleted":
                self.client.restore_experiment(found.experiment_id)
            return found
        try:
            self.client.create_experiment(name, artifact_location=self.location.artifact_location,
                                          tags={STORE_FORMAT_TAG: STORE_FORMAT})
        except Exception:
            # Another machine of the sweep created it first (our file lock is per machine).
            if self.client.get_experiment_by_name(name) is None:
                raise
        return self.client.get_experiment_by_name(name)

    def _write(self, call: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        with protected():
            return retry(call, *args, **kwargs)

    def start_run(self, name: str, tags: Mapping[str, str], parent_run_id: str | None = None,
                  description: str | None = None) -> str:
        tags = {**source_tags(), **{k: str(v) for k, v in tags.items()}}
        tags["host"], tags["pid"] = socket.gethostname(), str(os.getpid())
        if description:
            tags[NOTE] = description
        if parent_run_id:
            tags["mlflow.parentRunId"] = parent_run_id
        # A stop signal waits for the caller's next safe point: raised here, it would leave a RUNNING
        # run whose id nobody has, to close it KILLED.
        with deferred():
            run = self._write(self.client.create_run, self.experiment_id, tags=tags, run_name=name)
            # Until the lock is held, the pid tag says the run is alive (see `close_orphans`).
            self._hold(run.info.run_id)
        return run.info.run_id

    def reopen(self, run_id: str) -> None:
        """Mark an earlier, unfinished run RUNNING again under this process (resume).

        The run's lock is taken first: a job closing orphans at the same moment either closes
        the old attempt before this one reopens it, or finds the lock held and leaves it alone.
        A stop signal waits for the caller's next safe point, as in `start_run`.
        """
        with deferred():
            self._hold(run_id)
            self._write(self.client.update_run, run_id, status="RUNNING")
            self.set_tags(run_id, {"host": socket.gethostname(), "pid": str(os.getpid())})

    def end(self, run_id: str, status: str = "FINISHED") -> None:
        self._write(self.client.set_terminated, run_id, status=status)
        lock = self._held.pop(run_id, None)
        if lock is not None:
            Path(lock.lock_file).unlink(missing_ok=True)  # filelock copes with an unlinked lock file
            lock.release()

    def _run_lock(self, run_id: str) -> FileLock:
        self.location.run_locks.mkdir(parents=True, exist_ok=True)
        return FileLock(str(self.location.run_locks / f"{run_id}.lock"))

    def _hold(self, run_id: str) -> None:
        if run_id in self._held:
            return
        lock = self._run_lock(run_id)
        acquire_stoppably(lock, 0.5)
        self._held[run_id] = lock

    def set_tags(self, run_id: str, tags: Mapping[str, Any]) -> None:
        from mlflow.entities import RunTag

        self._write(self.client.log_batch, run_id, tags=[RunTag(k, str(v)) for k, v in tags.items()])

    def describe(self, run_id: str, description: str) -> None:
        """The run's description in the UI (markdown)."""
        self.set_tags(run_id, {NOTE: description})

    def log_params(self, run_id: str, params: Mapping[str, str]) -> None:
        from mlflow.entities import Param

        items = [Param(k, v) for k, v in params.items()]
        for chunk in _chunks(items, PARAMS_PER_BATCH):
            self._write(self.client.log_batch, run_id, params=chunk)

    def log_metrics(self, run_id: str, metrics: Mapping[str, float], step: int) -> None:
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        items = [Metric(k, tidy_number(v), now, int(step)) for k, v in metrics.items()]
        for chunk in _chunks(items, METRICS_PER_BATCH):
            self._write(self.client.log_batch, run_id, metrics=chunk)

    def log_artifact(self, run_id: str, path: Path, artifact_path: str | None = None) -> None:
        self._write(self.client.log_artifact, run_id, str(path), artifact_path)

    def log_text(self, run_id: str, text: str, artifact_file: str) -> None:
        self._write(self.client.log_text, run_id, text, artifact_file)

    def log_model(self, run_id: str, network: Any, name: str = "model") -> None:
        """The network as an MLflow PyTorch model of the run: `mlflow.pytorch.load_model(
        f"runs:/{run_id}/{name}")` gives it back, ready to call."""
        import mlflow
        import torch

        # log_model works only through MLflow's fluent (process-global) run; open ours just for it.
        mlflow.set_tracking_uri(self.location.tracking_uri)
        requirements = [f"torch=={torch.__version__.split('+')[0]}", "hgm_repro"]
        with protected(), mlflow.start_run(run_id=run_id), _quiet("mlflow.pytorch"):
            # pickle: the network class stays ours (pt2 would trace one fixed input shape). MLflow
            # warns about pickle on every call; docs/usage.md (Tracking in MLflow) says what loading it takes.
            retry(mlflow.pytorch.log_model, network.cpu().eval(), name=name, pip_requirements=requirements,
                  serialization_format="pickle")
        # Leaving the fluent run marks it FINISHED: the run's owner sets its real status afterwards.
        self._write(self.client.update_run, run_id, status="RUNNING")

    @contextmanager
    def system_metrics(self, run_id: str, enabled: bool) -> Iterator[None]:
        """While inside, log MLflow's system metrics (CPU, memory, disk, GPU: `system/*`) to the run."""
        if not enabled:
            yield
            return
        from mlflow.system_metrics.system_metrics_monitor import SystemMetricsMonitor

        monitor = SystemMetricsMonitor(run_id, sampling_interval=2, resume_logging=True,
                                       tracking_uri=self.location.tracking_uri)
        monitor.start()
        try:
            yield
        finally:
            monitor.finish()

    def best_value(self, run_id: str, metric: str) -> float | None:
        """The largest value a run logged for `metric` (None when it logged none)."""
        history = retry(self.client.get_metric_history, run_id, metric)
        values = [m.value for m in history if math.isfinite(m.value)]
        return max(values) if values else None

    def children(self, parent_run_id: str) -> list[Any]:
        return self.search(f"tags.`mlflow.parentRunId` = '{parent_run_id}'")

    def summarise_launch(self, parent_run_id: str, description: str) -> dict[str, float]:
        """The means over seeds of a launch's evaluations, per model and scenario, as a markdown
        table after `description` in its parent run's description; returned as
        `{"<model>/scenario<s>/<metric>": mean}`. Not logged as metrics: one chart per cell would
        bury the training curves in the UI's chart view."""
        groups: dict[tuple[str, str], list[Any]] = {}
        for run in self.children(parent_run_id):
            tags = run.data.tags
            if tags.get("stage") == "eval" and run.info.status == "FINISHED":
                groups.setdefault((tags.get("model", "?"), tags.get("scenario", "?")), []).append(run)
        summary: dict[str, float] = {}
        rows = ["| model | scenario | seeds | episode return | speed (km/h) | collisions |",
                "|---|---|---|---|---|---|"]
        for (model, scenario), runs in sorted(groups.items()):
            cells = []
            for metric in SUMMARY_METRICS:
                values = [r.data.metrics[f"eval/{metric}"] for r in runs if f"eval/{metric}" in r.data.metrics]
                mean = tidy_number(sum(values) / len(values)) if values else float("nan")
                if values:
                    summary[f"{model}/{scenario_label(scenario)}/{metric}"] = mean
                cells.append(f"{mean:.4g}")
            rows.append(f"| {model} | {scenario} | {len(runs)} | " + " | ".join(cells) + " |")
        if summary:
            description += "\n\nMeans over seeds of its evaluations:\n\n" + "\n".join(rows)
        self.describe(parent_run_id, description)
        return summary

    def get_run(self, run_id: str) -> Any | None:
        try:
            return retry(self.client.get_run, run_id)
        except Exception as error:  # deleted store, or a run id from another store
            log.debug("run %s not found: %s", run_id, error)
            return None

    def search(self, filter_string: str, max_results: int = 1000) -> list[Any]:
        return retry(
            self.client.search_runs, [self.experiment_id], filter_string=filter_string,
            max_results=max_results, order_by=["attributes.start_time DESC"],
        )

    def finished_trainings(self, train_key: str) -> list[Any]:
        """FINISHED training runs for this key, newest first."""
        return self.search(
            f"tags.stage = 'train' and tags.train_key = '{train_key}' and attributes.status = 'FINISHED'"
        )

    def finished_evaluation(self, evaluation_key: str, train_run_id: str | None) -> Any | None:
        """The newest FINISHED evaluation with this key (of this training run), if any."""
        found = self.search(f"tags.stage = 'eval' and tags.evaluation_key = '{evaluation_key}' "
                            "and attributes.status = 'FINISHED'")
        for run in found:
            if run.data.tags.get("train_run_id") == train_run_id:
                return run
        return None

    def logged_steps(self, run_id: str) -> dict[str, int]:
        """The last step logged of each metric of a run (what a resumed run must not log again)."""
        run = self.get_run(run_id)
        keys = list(run.data.metrics) if run is not None else []
        return {key: max((m.step for m in retry(self.client.get_metric_history, run_id, key)), default=-1)
                for key in keys}

    def close_orphans(self) -> list[str]:
        """Close as KILLED every RUNNING run of the experiment whose process is gone.

        A SIGKILLed job cannot close its runs; the next job that opens the store does, so that
        the store says what happened (a resumed training reopens its run). A run counts as
        alive while some process holds its lock file; a run without a lock file here (another
        machine, or a store shared without a shared launch dir) only when its host is this one
        and its pid tag names a live process.
        """
        host, closed = socket.gethostname(), []
        for run in self.search("attributes.status = 'RUNNING'"):
            run_id, tags = run.info.run_id, run.data.tags
            if run_id in self._held:
                continue
            lock_file = self.location.run_locks / f"{run_id}.lock"
            if lock_file.exists():
                lock = FileLock(str(lock_file))
                try:
                    lock.acquire(timeout=0)
                except Timeout:
                    continue  # a live process holds it
                try:
                    now = self.get_run(run_id)  # read again under the lock: it may have ended meanwhile
                    if now is not None and now.info.status == "RUNNING":
                        self._write(self.client.set_terminated, run_id, status="KILLED")
                        closed.append(run_id)
                    lock_file.unlink(missing_ok=True)
                finally:
                    lock.release()
            elif tags.get("host") == host and tags.get("pid", "").isdigit() and not _alive(int(tags["pid"])):
                self._write(self.client.set_terminated, run_id, status="KILLED")
                closed.append(run_id)
        return closed

    def download(self, run_id: str, artifact_path: str, dst: Path) -> Path:
        dst.mkdir(parents=True, exist_ok=True)
        os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")  # a bar per file is noise in a log
        return Path(retry(self.client.download_artifacts, run_id, artifact_path, str(dst)))


def shared_view(key: str) -> str:
    """The experiment tag value of view `key` of `SHARED_VIEWS`, in MLflow's saved-view envelope."""
    now = int(time.time() * 1000)
    return json.dumps({"name": VIEW_NAMES[key], "createdAt": now, "updatedAt": now,
                       "state": json.dumps(SHARED_VIEWS[key])})


@contextmanager
def _quiet(logger: str) -> Iterator[None]:
    """Only errors from `logger` while inside (MLflow's per-call warnings and notices)."""
    target = logging.getLogger(logger)
    level = target.level
    target.setLevel(logging.ERROR)
    try:
        yield
    finally:
        target.setLevel(level)


def _create_sqlite_store_atomically(uri: str) -> None:
    """Make a new SQLite store under another name and rename it into place.

    MLflow creates a store by running its schema migrations, many statements long: a job killed
    in the middle would leave a half-made store that no later job can open.
    """
    from mlflow.tracking import MlflowClient

    prefix = "sqlite:///"
    if not uri.startswith(prefix):
        return
    db = Path(uri[len(prefix):])
    if db.exists():
        return
    db.parent.mkdir(parents=True, exist_ok=True)
    for stale in db.parent.glob(f".{db.name}.creating-*"):  # what killed creators left (we hold the store lock)
        stale.unlink(missing_ok=True)
    tmp = db.with_name(f".{db.name}.creating-{os.getpid()}")
    with _quiet("mlflow.store.db.utils"), _quiet("alembic"):
        MlflowClient(tracking_uri=f"{prefix}{tmp}").search_experiments(max_results=1)  # runs the migrations
    os.replace(tmp, db)


def _store_problem(uri: str, error: Exception) -> str:
    """One line on why MLflow cannot open the store, saying so when another version wrote it."""
    import mlflow

    text = " ".join(str(error).split())
    lowered = text.lower()
    if "schema" in lowered or "revision" in lowered or "alembic" in lowered or "upgrade" in lowered:
        return (f"the MLflow store {uri} was written by another version of MLflow (this is mlflow "
                f"{mlflow.__version__}, which hgm_repro pins): {text}. Use the version that wrote it, back "
                f"the store up and run `mlflow db upgrade {uri}`, or use another tracking.uri.")
    return f"cannot open the MLflow store {uri}: {text}"


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True
