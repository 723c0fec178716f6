"""The traffic mix of each test scenario, as its evaluation runs logged it (`scenario.ratios.*`).

The report and the figures place a scenario by the connected-vehicle share it ran with, so that a
user's own scenario (or an edited Table 5) is drawn where it belongs. Runs that logged no mix (a
bundle written before the params were kept) fall back to the paper's Table 5.
"""

from __future__ import annotations

import pandas as pd

# The paper's Table 5: the connected-vehicle (NCV) share of each test scenario; AHV and CHV share
# the rest equally. Only for runs that logged no mix, and as the paper's side of a comparison.
PAPER_CV_RATIO = {"1": 0.0, "2": 0.25, "3": 0.5, "4": 0.75, "5": 1.0}
TYPES = ("NCV", "AHV", "CHV")


def scenario_mix(runs: pd.DataFrame | None) -> pd.DataFrame:
    """One row per test scenario (index: its name), columns NCV, AHV, CHV: the shares its evaluation
    runs logged; empty when they logged none."""
    columns = [f"params.scenario.ratios.{t}" for t in TYPES]
    if runs is None or runs.empty or "stage" not in runs or not set(columns) <= set(runs.columns):
        return pd.DataFrame(columns=list(TYPES), dtype=float)
    evals = runs[runs["stage"] == "eval"].dropna(subset=columns)
    mix = evals.assign(scenario=evals["scenario"].astype(str)).groupby("scenario")[columns].first().astype(float)
    mix.columns = list(TYPES)
    return mix


def cv_ratios(runs: pd.DataFrame | None) -> dict[str, float]:
    """Scenario name -> its connected-vehicle share: logged, else Table 5's for the paper's scenarios."""
    return {**PAPER_CV_RATIO, **scenario_mix(runs)["NCV"].to_dict()}


def with_cv_ratio(evals: pd.DataFrame, runs: pd.DataFrame | None) -> pd.DataFrame:
    """`evals` with a `cv_ratio` column (NaN for a scenario with neither a logged mix nor a Table 5 row)."""
    return evals.assign(cv_ratio=evals["scenario"].astype(str).map(cv_ratios(runs)))
