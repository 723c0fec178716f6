"""Several results read as one: the published grid and a variant run later, into one report.

A variant (a model that departs from the paper, say) is trained in a store of its own, after the
grid was published; its bundle is then read beside the grid's bundle, and the report shows both.
Sources combine by whole cells of (model, experiment preset): when two hold the same model at the same
preset, the later one's runs of it replace the earlier one's (a re-run of a variant replaces its first
publication), and the report's notes say so, so that nothing is mixed silently. The same model at
another preset (a rung of the scale ladder beside the quick grid) is kept beside it.
"""

from __future__ import annotations

import pandas as pd
import yaml

from analysis.load import UNKNOWN_EXPERIMENT, StoreData, run_experiments

# The StoreData tables, each with a `model` column.
_TABLES = ("runs", "curves", "evals", "episodes", "stopped")


def _presets(data: StoreData, frame: pd.DataFrame) -> pd.Series:
    """The experiment preset of each row of `frame`, as its evaluations name it: an eval row's own
    `experiment`; a row naming an eval run (episodes, the eval runs) that run's; a row naming a training
    (curves, the training runs) the preset of the evaluations of that `train_key`; else the run's own
    preset param or tag; else unknown."""
    if "experiment" in frame.columns:
        return frame["experiment"].fillna(UNKNOWN_EXPERIMENT).astype(str)
    evals = data.evals
    out = pd.Series(pd.NA, index=frame.index, dtype=object)
    if "experiment" in evals.columns:
        if "run_id" in frame.columns and "run_id" in evals.columns:
            firsts = evals.drop_duplicates("run_id")
            by_run = pd.Series(firsts["experiment"].to_numpy(), index=firsts["run_id"].astype(str))
            out = frame["run_id"].astype(str).map(by_run)
        if "train_key" in frame.columns and "train_key" in evals.columns:
            firsts = evals.dropna(subset=["train_key"]).drop_duplicates("train_key")
            by_key = pd.Series(firsts["experiment"].to_numpy(), index=firsts["train_key"].astype(str))
            out = out.fillna(frame["train_key"].astype(str).map(by_key))
    if "run_id" in frame.columns and "run_id" in data.runs.columns:
        own = pd.Series(run_experiments(data.runs).to_numpy(), index=data.runs["run_id"].astype(str))
        own = own[~own.index.duplicated()]
        out = out.fillna(frame["run_id"].astype(str).map(own))
    return out.fillna(UNKNOWN_EXPERIMENT).astype(str)


def _keys(data: StoreData, frame: pd.DataFrame) -> pd.Series:
    return frame["model"].astype(str) + "\x00" + _presets(data, frame)


def _cells(data: StoreData) -> set[tuple[str, str]]:
    """The (model, preset) cells `data` holds runs of."""
    found: set[tuple[str, str]] = set()
    for name in _TABLES:
        frame: pd.DataFrame = getattr(data, name)
        if "model" in frame.columns:
            rows = frame[frame["model"].notna()]
            found |= set(zip(rows["model"].astype(str), _presets(data, rows), strict=True))
    return found


def _without(data: StoreData, cells: set[tuple[str, str]]) -> dict[str, pd.DataFrame]:
    out = {}
    keys = {f"{model}\x00{preset}" for model, preset in cells}
    for name in _TABLES:
        frame: pd.DataFrame = getattr(data, name)
        if "model" in frame.columns and cells:
            frame = frame[~_keys(data, frame).isin(keys)]
        out[name] = frame
    return out


def _unique_join(values: list[str]) -> str:
    # A combined source's value is itself such a join: split it, so that no name repeats.
    return "; ".join(dict.fromkeys(part for v in values for part in v.split("; ") if part))


def config_preset(text: str) -> str:
    """The experiment preset a resolved config names (`experiment.name`), else UNKNOWN_EXPERIMENT."""
    try:
        node = yaml.safe_load(text)
    except yaml.YAMLError:
        return UNKNOWN_EXPERIMENT
    experiment = node.get("experiment") if isinstance(node, dict) else None
    name = experiment.get("name") if isinstance(experiment, dict) else None
    return str(name) if name else UNKNOWN_EXPERIMENT


def combine(parts: list[StoreData]) -> StoreData:
    """`parts` as one StoreData; a (model, preset) cell held by a later part replaces that cell's runs of
    earlier parts."""
    if not parts:
        raise ValueError("combine needs at least one source")
    if len(parts) == 1:
        return parts[0]
    names = [p.source or p.tracking_uri for p in parts]
    kept: list[dict[str, pd.DataFrame]] = []
    configs: dict[str, str] = {}
    dropped: list[str] = []
    for i, part in enumerate(parts):
        later = set().union(*(_cells(p) for p in parts[i + 1:]))
        replaced = sorted(_cells(part) & later)
        for model, preset in replaced:
            at = "" if preset == UNKNOWN_EXPERIMENT else f" ({preset})"
            dropped.append(f"model {model}{at} of {names[i]} replaced by a later source's runs of it")
        kept.append(_without(part, set(replaced)))
        for model, text in part.configs.items():
            # One config per model: a later source's replaces it when it is of the same preset (a cell
            # published again), not when it is a rung at another preset beside the model's grid, whose
            # config the report describes the grid by.
            if model not in configs or config_preset(configs[model]) == config_preset(text):
                configs[model] = text
        dropped += part.dropped
    tables = {}
    for name in _TABLES:
        frames = [k[name] for k in kept if not k[name].empty]
        tables[name] = (pd.concat(frames, ignore_index=True) if frames
                        else getattr(parts[0], name).iloc[0:0].reset_index(drop=True))
    return StoreData(tracking_uri=_unique_join([p.tracking_uri for p in parts]),
                     experiment=_unique_join([p.experiment for p in parts]), configs=configs,
                     dropped=list(dict.fromkeys(dropped)),  # a variant published twice notes it once
                     source=" + ".join(names), **tables)
