"""Training curves on a common step grid, and the per-seed numbers claims are tested on.

Runs log at their own steps (episodes end at different times, seeds differ), so curves are
averaged inside bins of a grid shared by all runs before seeds are compared step by step.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

N_BINS = 40
FINAL_FRACTION = 0.1  # "where training ended": the last 10 % of each run's steps


def bin_curves(curves: pd.DataFrame, metric: str, n_bins: int = N_BINS) -> pd.DataFrame:
    """Mean of each run's logged values inside equal-width step bins: model, seed, step, value."""
    part = curves[curves["metric"] == metric]
    if part.empty:
        return pd.DataFrame(columns=["model", "seed", "run_id", "step", "value"])
    top = float(part["step"].max())
    edges = np.linspace(0.0, top if top > 0 else 1.0, n_bins + 1)
    centres = (edges[:-1] + edges[1:]) / 2
    idx = np.clip(np.searchsorted(edges, part["step"].to_numpy(), side="right") - 1, 0, n_bins - 1)
    binned = (part.assign(bin=idx).groupby(["model", "seed", "run_id", "bin"], as_index=False)["value"].mean())
    binned["step"] = centres[binned["bin"].to_numpy()]
    return binned.drop(columns="bin")


def final_values(curves: pd.DataFrame, metric: str, fraction: float = FINAL_FRACTION) -> pd.DataFrame:
    """Per run: mean of the values logged in the last `fraction` of its steps."""
    part = curves[curves["metric"] == metric]
    rows = []
    for (model, seed, run_id), group in part.groupby(["model", "seed", "run_id"]):
        cut = group["step"].max() * (1.0 - fraction)
        rows.append({"model": model, "seed": seed, "run_id": run_id,
                     "value": float(group.loc[group["step"] >= cut, "value"].mean())})
    return pd.DataFrame(rows, columns=["model", "seed", "run_id", "value"])


def area_values(curves: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per run: mean of the binned curve up to the step every run reached (a normalised area).

    A method that gets good sooner has a larger area for the same final value: this is the
    learning-speed measure. Cutting at the shortest run keeps an unfinished run from being
    compared over steps it never saw.
    """
    part = curves[curves["metric"] == metric]
    if part.empty:
        return pd.DataFrame(columns=["model", "seed", "run_id", "value"])
    common = part.groupby("run_id")["step"].max().min()
    binned = bin_curves(part[part["step"] <= common], metric)
    values = binned.groupby(["model", "seed", "run_id"], as_index=False)["value"].mean()
    return values


def fluctuation_values(curves: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per run: standard deviation of the binned curve's bin-to-bin changes.

    A steadily rising curve scores low; one that jumps up and down between neighbouring bins
    scores high, whatever its level. Each model's runs are binned on a grid of their own length, so
    that a run's number does not move when a longer run of another model (a variant) joins the data.
    """
    part = curves[curves["metric"] == metric]
    binned = (pd.concat([bin_curves(group, metric) for _, group in part.groupby("model")], ignore_index=True)
              if not part.empty else bin_curves(part, metric))
    rows = []
    for (model, seed, run_id), group in binned.groupby(["model", "seed", "run_id"]):
        steps = np.diff(group.sort_values("step")["value"].to_numpy())
        rows.append({"model": model, "seed": seed, "run_id": run_id,
                     "value": float(np.std(steps, ddof=1)) if steps.size >= 2 else np.nan})
    return pd.DataFrame(rows, columns=["model", "seed", "run_id", "value"])


def by_model(values: pd.DataFrame, model: str) -> dict[str, pd.Series]:
    """One stratum ('train') of per-seed values indexed by seed, the shape the stats functions take."""
    part = values[(values["model"] == model) & np.isfinite(values["value"].astype(float))]
    series = part.groupby("seed")["value"].mean().astype(float)
    return {"train": series} if series.size else {}
