"""Several results read as one: the published grid and a variant run later, into one report.

A variant (a model that departs from the paper, say) is trained in a store of its own, after the
grid was published; its bundle is then read beside the grid's bundle, and the report shows both.
Sources combine by whole models: when two hold the same model, the later one's runs of that model
replace the earlier one's (a re-run of a variant replaces its first publication), and the report's
notes say so, so that nothing is mixed silently.
"""

from __future__ import annotations

import pandas as pd

from analysis.load import StoreData

# The StoreData tables, each with a `model` column.
_TABLES = ("runs", "curves", "evals", "episodes")


def _models(data: StoreData) -> set[str]:
    found: set[str] = set(data.configs)
    for name in _TABLES:
        frame: pd.DataFrame = getattr(data, name)
        if "model" in frame.columns:
            found |= {str(m) for m in frame["model"].dropna().unique()}
    return found


def _without(data: StoreData, models: set[str]) -> dict[str, pd.DataFrame]:
    out = {}
    for name in _TABLES:
        frame: pd.DataFrame = getattr(data, name)
        if "model" in frame.columns and models:
            frame = frame[~frame["model"].astype("string").isin(sorted(models)).fillna(False)]
        out[name] = frame
    return out


def _unique_join(values: list[str]) -> str:
    # A combined source's value is itself such a join: split it, so that no name repeats.
    return "; ".join(dict.fromkeys(part for v in values for part in v.split("; ") if part))


def combine(parts: list[StoreData]) -> StoreData:
    """`parts` as one StoreData; a model held by a later part replaces that model's runs of earlier parts."""
    if not parts:
        raise ValueError("combine needs at least one source")
    if len(parts) == 1:
        return parts[0]
    names = [p.source or p.tracking_uri for p in parts]
    kept: list[dict[str, pd.DataFrame]] = []
    configs: dict[str, str] = {}
    dropped: list[str] = []
    for i, part in enumerate(parts):
        later = set().union(*(_models(p) for p in parts[i + 1:]))
        replaced = sorted(_models(part) & later)
        for model in replaced:
            dropped.append(f"model {model} of {names[i]} replaced by a later source's runs of it")
        kept.append(_without(part, set(replaced)))
        configs.update({m: text for m, text in part.configs.items() if m not in later})
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
