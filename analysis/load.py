"""Read the MLflow tracking store into pandas tables.

Only this module talks to MLflow; everything downstream works on the `StoreData` tables, so
the figures, statistics and report can be tested on plain DataFrames.
"""

from __future__ import annotations

import io
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from mlflow import MlflowClient
from mlflow.entities import ViewType

from analysis.costs import hours_trained, slowest_rate
from hgm_repro.contracts.names import REPORTED_METRICS as EVAL_METRICS  # after the `eval/` prefix, in table order
from hgm_repro.contracts.names import RUN_TAGS as TAG_COLUMNS
from hgm_repro.contracts.names import SAFEST_TAGS, current_key

# The experiment preset a run was made with (`quick`, `paper_steps`, ...): its resolved `experiment.name`,
# else the `preset` tag every run of the app carries, else this.
EXPERIMENT_PARAM = "params.experiment.name"
PRESET_TAG = "preset"
RESUMES_TAG = "resumes"  # on a training run: how many times it was stopped and resumed
UNKNOWN_EXPERIMENT = "unknown"
TOTAL_STEPS_PARAM = "params.learner.total_steps"
# A training stopped before its last step, by a signal (its run KILLED, its last.pt resumes it), or still
# running when the store was read: what it
# reached and what it cost so far (`analysis.costs`: CPU hours where logged). `step`: the last env step it
# logged; `steps_per_s`: the slowest rate it logged, per CPU second where logged (what the rest of it would
# go at); `stops`: its runs' `resumes` tag.
STOPPED_COLUMNS = ["run_id", "model", "seed", "experiment", "train_key", "step", "total_steps", "steps_per_s",
                   "hours", "stops"]


def no_stopped() -> pd.DataFrame:
    """The stopped-trainings table with no rows."""
    return pd.DataFrame(columns=STOPPED_COLUMNS)


class EmptyStoreError(RuntimeError):
    """The store holds no experiment of that name, or no run of it carries a `stage` tag."""


@dataclass
class StoreData:
    """Everything the analysis reads from one experiment of a tracking store."""

    tracking_uri: str
    experiment: str
    runs: pd.DataFrame  # one row per kept run: tags, status, params.<key>, metrics.<key>
    curves: pd.DataFrame  # long: run_id, model, seed, train_key, metric, step, value
    evals: pd.DataFrame  # one row per (model, scenario, seed): run_id and EVAL_METRICS columns
    episodes: pd.DataFrame  # one row per evaluated episode: model, scenario, seed, episode, metrics
    configs: dict[str, str] = field(default_factory=dict)  # model -> resolved config.yaml text
    dropped: list[str] = field(default_factory=list)  # why runs were left out (duplicates, failures)
    source: str = ""  # how the report names where the data came from; "" = the tracking store
    stopped: pd.DataFrame = field(default_factory=no_stopped)  # STOPPED_COLUMNS: trainings under way

    def __post_init__(self) -> None:
        # Every source gets the evals' `experiment` column the same way, older bundles included.
        self.evals = with_experiment(self.evals, self.runs)

    @property
    def git_dirty(self) -> str:
        """'true', 'false', 'mixed', or '' when the runs did not record it."""
        flags = set(self.runs.get("git_dirty", pd.Series(dtype=str)).dropna().astype(str))
        return "" if not flags else flags.pop() if len(flags) == 1 else "mixed"

    @property
    def git_commits(self) -> list[str]:
        commits = self.runs.get("git_commit", pd.Series(dtype=str)).dropna().astype(str)
        return sorted(c for c in commits.unique() if c)


def run_experiments(runs: pd.DataFrame) -> pd.Series:
    """The experiment preset of each run, indexed like `runs`: its `experiment.name` param, else its `preset`
    tag, else 'unknown'."""
    out = pd.Series(UNKNOWN_EXPERIMENT, index=runs.index, dtype=object)
    for column in (PRESET_TAG, EXPERIMENT_PARAM):  # the param, read last, wins
        if column in runs:
            values = runs[column]
            given = values.notna() & values.astype(str).str.strip().ne("")
            out[given] = values[given].astype(str)
    return out


def with_experiment(evals: pd.DataFrame, runs: pd.DataFrame) -> pd.DataFrame:
    """`evals` with an `experiment` column (after `seed`): each row's preset, from its run in `runs`; a row
    that already names one keeps it."""
    if "run_id" in runs and "run_id" in evals and not runs.empty:
        by_run = pd.Series(run_experiments(runs).to_numpy(), index=runs["run_id"].astype(str))
        by_run = by_run[~by_run.index.duplicated()]
        derived = evals["run_id"].astype(str).map(by_run).fillna(UNKNOWN_EXPERIMENT)
    else:
        derived = pd.Series(UNKNOWN_EXPERIMENT, index=evals.index, dtype=object)
    if "experiment" in evals:
        known = evals["experiment"].notna() & evals["experiment"].astype(str).ne("")
        if known.all():
            return evals
        evals = evals.copy()
        evals["experiment"] = evals["experiment"].where(known, derived).astype(str)
        return evals
    evals = evals.copy()
    at = list(evals.columns).index("seed") + 1 if "seed" in evals else len(evals.columns)
    evals.insert(at, "experiment", derived.astype(str).to_numpy())
    return evals


def main_experiments(evals: pd.DataFrame) -> dict[str, str]:
    """Per model, the experiment its runs on the report's main pages come from: of the model's own
    experiments, the one most evaluation runs of the whole store were made with (ties: by name). A model
    run at several presets (the rungs of the scale ladder) is thus never pooled across them."""
    if evals.empty or "experiment" not in evals:
        return {}
    counts = evals["experiment"].astype(str).value_counts()
    return {str(model): sorted(set(group.astype(str)), key=lambda e: (-counts[e], e))[0]
            for model, group in evals.groupby("model")["experiment"]}


def at_main_experiments(evals: pd.DataFrame) -> pd.DataFrame:
    """The rows of `evals` at each model's main experiment preset: what every page but the scale ladder reads."""
    main = main_experiments(evals)
    return evals[[main.get(str(m)) == e for m, e in zip(evals["model"], evals["experiment"], strict=True)]]


def default_tracking_uri() -> str:
    # Same default as the main app: a SQLite file in the directory the command started from.
    return f"sqlite:///{Path(os.getcwd()).resolve() / 'mlflow.db'}"


def _seed_value(raw: object) -> object:
    try:
        return int(str(raw))
    except (TypeError, ValueError):
        return raw


def _runs_frame(client: MlflowClient, experiment_id: str) -> pd.DataFrame:
    rows = []
    token = None
    while True:
        page = client.search_runs([experiment_id], run_view_type=ViewType.ACTIVE_ONLY, max_results=1000,
                                  page_token=token)
        for run in page:
            tags = run.data.tags
            row: dict[str, object] = {
                "run_id": run.info.run_id,
                "run_name": run.info.run_name,
                "status": run.info.status,
                "start_time": run.info.start_time or 0,
                "parent_run_id": tags.get("mlflow.parentRunId"),
            }
            for tag in (*TAG_COLUMNS, PRESET_TAG, RESUMES_TAG, *SAFEST_TAGS):
                row[tag] = tags.get(tag)
            row.update({f"params.{current_key(k)}": v for k, v in run.data.params.items()})  # old names too
            row.update({f"metrics.{k}": v for k, v in run.data.metrics.items()})
            rows.append(row)
        token = page.token
        if not token:
            break
    frame = pd.DataFrame(rows)
    if frame.empty or "stage" not in frame:
        return pd.DataFrame(columns=["run_id", "status", "start_time", *TAG_COLUMNS])
    # Parent sweep runs carry no stage tag: they hold no results of their own.
    frame = frame[frame["stage"].notna()].copy()
    frame["seed"] = frame["seed"].map(_seed_value)
    frame["scenario"] = frame["scenario"].astype("string").fillna("")
    return frame.reset_index(drop=True)


def _keep_latest(runs: pd.DataFrame, keys: list[str], what: str) -> tuple[pd.DataFrame, list[str]]:
    """One run per key: the latest finished one, else the latest of any status.

    Re-runs of the same cell (a crashed job restarted, a sweep repeated) would otherwise count
    as extra seeds and shrink the confidence intervals.
    """
    if runs.empty:
        return runs, []
    ordered = runs.assign(_finished=runs["status"].eq("FINISHED"))
    ordered = ordered.sort_values(["_finished", "start_time"], ascending=[False, False])
    kept = ordered.drop_duplicates(keys, keep="first").drop(columns="_finished")
    notes = []
    n_dup = len(runs) - len(kept)
    if n_dup:
        notes.append(f"{n_dup} duplicate {what} run(s) for the same {'/'.join(keys)} left out (latest kept)")
    unfinished = kept[~kept["status"].eq("FINISHED")]
    if len(unfinished):
        notes.append(f"{len(unfinished)} {what} run(s) not FINISHED used as they are "
                     f"(status: {', '.join(sorted(unfinished['status'].unique()))})")
    return kept.reset_index(drop=True), notes


def _curves(client: MlflowClient, train_runs: pd.DataFrame) -> pd.DataFrame:
    frames = []
    # to_dict, not itertuples: column names such as "metrics.train/loss" are not identifiers.
    for run in train_runs.to_dict("records"):
        keys = [c[len("metrics."):] for c, v in run.items()
                if c.startswith("metrics.train/") and v is not None and not pd.isna(v)]
        for key in keys:
            history = client.get_metric_history(run["run_id"], key)
            if not history:
                continue
            frames.append(pd.DataFrame({
                "run_id": run["run_id"],
                "model": run["model"],
                "seed": run["seed"],
                "train_key": run["train_key"],
                "metric": key.removeprefix("train/"),
                "step": [m.step for m in history],
                "value": [m.value for m in history],
            }))
    if not frames:
        return pd.DataFrame(columns=["run_id", "model", "seed", "train_key", "metric", "step", "value"])
    curves = pd.concat(frames, ignore_index=True)
    return curves.sort_values(["model", "seed", "metric", "step"]).reset_index(drop=True)


def _artifact_names(client: MlflowClient, run_id: str) -> set[str]:
    try:
        return {a.path for a in client.list_artifacts(run_id)}
    except Exception:  # an unreachable artifact store must not stop the metric tables
        return set()


def _download_text(client: MlflowClient, run_id: str, name: str, tmp: Path) -> str | None:
    try:
        local = client.download_artifacts(run_id, name, str(tmp))
        return Path(local).read_text()
    except Exception:
        return None


def _evals_and_episodes(client: MlflowClient, eval_runs: pd.DataFrame,
                        tmp: Path) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, str]]:
    eval_rows, episode_frames, configs = [], [], {}
    # Each model's printed config comes from a run of its main experiment: the runs of that one are read first.
    experiments = run_experiments(eval_runs)
    main = main_experiments(pd.DataFrame({"model": eval_runs["model"], "experiment": experiments}))
    first = [e == main.get(str(m)) for e, m in zip(experiments, eval_runs["model"], strict=True)]
    order = sorted(range(len(eval_runs)), key=lambda i: not first[i])
    records = eval_runs.to_dict("records")
    for i in order:
        run = records[i]
        row = {k: run.get(k) for k in ("run_id", "model", "scenario", "seed", "train_key", "git_commit")}
        for metric in EVAL_METRICS:
            value = run.get(f"metrics.eval/{metric}")
            row[metric] = np.nan if value is None or pd.isna(value) else float(value)
        run_id = str(run["run_id"])
        artifacts = _artifact_names(client, run_id)
        row["n_episodes"] = np.nan
        if "episodes.csv" in artifacts:
            text = _download_text(client, run_id, "episodes.csv", tmp / run_id)
            if text:
                episodes = pd.read_csv(io.StringIO(text))
                episodes.columns = [c.removeprefix("eval/") for c in episodes.columns]
                row["n_episodes"] = len(episodes)
                # A run that logged the table but not a mean still gets its mean from the table.
                for metric in EVAL_METRICS:
                    if np.isnan(row[metric]) and metric in episodes:
                        row[metric] = float(episodes[metric].mean())
                if "episode.1" in episodes:  # older versions wrote the row index as a first `episode` column
                    episodes = episodes.drop(columns="episode").rename(columns={"episode.1": "episode"})
                if "episode" not in episodes:
                    episodes.insert(0, "episode", range(len(episodes)))
                episodes = episodes.drop(columns=[c for c in ("seed", "scenario", "model", "run_id")
                                                  if c in episodes])
                for key in ("seed", "scenario", "model", "run_id"):
                    episodes.insert(0, key, row[key])
                episode_frames.append((i, episodes))
        if str(run["model"]) not in configs and "config.yaml" in artifacts:
            text = _download_text(client, run_id, "config.yaml", tmp / run_id)
            if text:
                configs[str(run["model"])] = text
        eval_rows.append((i, row))
    # Back in the runs' order: the reading order only chose the configs.
    eval_rows = [row for _, row in sorted(eval_rows, key=lambda pair: pair[0])]
    episode_frames = [frame for _, frame in sorted(episode_frames, key=lambda pair: pair[0])]
    evals = pd.DataFrame(eval_rows, columns=["run_id", "model", "scenario", "seed", "train_key", "git_commit",
                                             *EVAL_METRICS, "n_episodes"])
    episodes = pd.concat(episode_frames, ignore_index=True) if episode_frames else pd.DataFrame(
        columns=["run_id", "model", "scenario", "seed", "episode"])
    return evals, episodes, configs


def load_store(tracking_uri: str | None = None, experiment: str = "hgm_repro") -> StoreData:
    """Read one experiment of a tracking store. Raises `EmptyStoreError` when there is nothing to analyse."""
    # One progress bar per downloaded artifact would bury the command's output.
    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
    uri = tracking_uri or default_tracking_uri()
    if uri.startswith("sqlite:///"):
        # MLflow would silently create an empty database here; a missing file is a user error.
        db = Path(uri.removeprefix("sqlite:///"))
        if not db.exists():
            raise EmptyStoreError(f"no tracking store at {db} (give --tracking-uri, or run from the directory "
                                  "holding mlflow.db)")
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        raise EmptyStoreError(f"no experiment named {experiment!r} in the tracking store {uri}")
    runs = _runs_frame(client, exp.experiment_id)
    if runs.empty:
        raise EmptyStoreError(f"experiment {experiment!r} in {uri} has no runs tagged with a stage "
                              "(train/eval): run `python -m hgm_repro` first")
    # Failed and killed runs hold partial results that would bias the means. A training run still RUNNING
    # (the store read while it trains, or a job stopped before it could close its run) is under way, as a
    # KILLED one is: its curves are a part, never the training's.
    ended_badly = runs["status"].isin(["FAILED", "KILLED"])
    under_way = runs["stage"].eq("train") & runs["status"].eq("RUNNING")
    bad = ended_badly | under_way
    dropped = [f"{int(ended_badly.sum())} FAILED/KILLED run(s) left out"] if ended_badly.any() else []
    if under_way.any():
        dropped.append(f"{int(under_way.sum())} training run(s) still RUNNING left out, read as under way")
    stopped = _stopped(client, runs)
    runs = runs[~bad]
    # A model trained and tested at several presets keeps one run per cell of each.
    runs = runs.assign(experiment=run_experiments(runs))
    train, notes_t = _keep_latest(runs[runs["stage"] == "train"], ["model", "seed", "experiment"], "train")
    evals_runs, notes_e = _keep_latest(runs[runs["stage"] == "eval"], ["model", "scenario", "seed", "experiment"],
                                       "eval")
    train, evals_runs = train.drop(columns="experiment"), evals_runs.drop(columns="experiment")
    dropped += notes_t + notes_e
    with tempfile.TemporaryDirectory(prefix="hgm_analysis_") as tmp:
        evals, episodes, configs = _evals_and_episodes(client, evals_runs, Path(tmp))
    curves = _curves(client, train)
    kept = pd.concat([train, evals_runs], ignore_index=True)
    return StoreData(tracking_uri=uri, experiment=experiment, runs=kept, curves=curves, evals=evals,
                     episodes=episodes, configs=configs, dropped=dropped, stopped=stopped)


def _numbers(frame: pd.DataFrame, column: str) -> pd.Series:
    """`frame[column]` as numbers (NaN where absent or not a number)."""
    if column not in frame:
        return pd.Series(np.nan, index=frame.index)
    return pd.to_numeric(frame[column], errors="coerce")


def _stopped(client: MlflowClient, runs: pd.DataFrame) -> pd.DataFrame:
    """The trainings under way: stopped before their last step (KILLED training runs: each resumes from its
    last.pt, in the same run) or still RUNNING, one per (model, seed, experiment preset), the latest; none
    that another run of the same training finished."""
    train = runs[runs["stage"] == "train"].assign(experiment=run_experiments(runs))
    under_way = train[train["status"].isin(["KILLED", "RUNNING"])]
    finished = set(train.loc[train["status"] == "FINISHED", "train_key"].dropna())
    under_way = under_way[~under_way["train_key"].isin(finished)]
    if under_way.empty:
        return no_stopped()
    under_way = under_way.sort_values("start_time", ascending=False).drop_duplicates(["model", "seed", "experiment"])
    curves = _curves(client, under_way)
    hours = hours_trained(curves)
    last_step = curves.groupby("train_key")["step"].max() if not curves.empty else pd.Series(dtype=float)
    out = pd.DataFrame({
        "run_id": under_way["run_id"].astype(str),
        "model": under_way["model"].astype(str),
        "seed": under_way["seed"],
        "experiment": under_way["experiment"].astype(str),
        "train_key": under_way["train_key"],
        "step": under_way["train_key"].map(last_step).fillna(0).astype(int),
        "total_steps": _numbers(under_way, TOTAL_STEPS_PARAM).astype(float),
        "steps_per_s": under_way["train_key"].map(slowest_rate(curves)).astype(float),
        "hours": under_way["train_key"].map(hours).fillna(0.0).astype(float),
        "stops": _numbers(under_way, RESUMES_TAG).fillna(0).astype(int),
    }, columns=STOPPED_COLUMNS)
    return out.sort_values(["experiment", "model", "seed"]).reset_index(drop=True)
