"""Test-result tables (the paper's Table 6 and every metric beside it) with CIs over seeds."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.labels import fmt, model_label, ordered_models, ordered_scenarios
from analysis.load import EVAL_METRICS
from analysis.stats import (
    NO_DATA,
    Estimate,
    iqm,
    mean_ci,
    probability_of_improvement,
    stratified_mean_ci,
    test_noise_ci,
)

# The paper's Table 6 (test score per scenario; the paper does not name the unit).
PAPER_TABLE6 = pd.DataFrame(
    {"1": [1927, 1911, 1868], "2": [1937, 1893, 1893], "3": [1950, 1901, 1867],
     "4": [1974, 1907, 1875], "5": [1969, 1903, 1907]},
    index=pd.Index(["proposed", "min", "coordinate"], name="model"),
)


def per_scenario(evals: pd.DataFrame, model: str, metric: str,
                 scenarios: list[str] | None = None) -> dict[str, pd.Series]:
    """Per-seed values of one metric for one model, keyed by scenario, each a Series indexed by seed
    (so that two methods pair seed by seed: the same seed drew the same test traffic)."""
    rows = evals[(evals["model"] == model) & evals[metric].notna()] if metric in evals else evals.iloc[:0]
    out = {}
    for scenario, group in rows.groupby("scenario"):
        if scenarios is None or str(scenario) in scenarios:
            out[str(scenario)] = group.groupby("seed")[metric].mean().astype(float)
    return out


# The range a metric's mean lies in: counts, speeds and distances are never negative, and collisions per episode
# is a share of episodes (an episode ends at the host's first collision), so it never passes 1. A t interval
# reaching past its range is cut there: the true mean lies inside, so the cut loses no coverage; it only stops
# a table printing an impossible value.
RANGES = {"avg_speed_kmh": (0.0, math.inf), "lane_changes": (0.0, math.inf), "overtakes": (0.0, math.inf),
          "collisions": (0.0, 1.0), "dangerous_actions": (0.0, math.inf), "distance_m": (0.0, math.inf)}


def in_range(est: Estimate, metric: str) -> Estimate:
    """`est` with its interval cut to the range `metric`'s mean can take (unchanged without a range or a CI)."""
    if metric not in RANGES or not est.has_ci:
        return est
    bottom, top = RANGES[metric]
    return Estimate(est.point, min(max(est.low, bottom), top), max(min(est.high, top), bottom), est.n)


def summary(evals: pd.DataFrame, metrics: tuple[str, ...] = EVAL_METRICS) -> pd.DataFrame:
    """Long table: model, scenario, metric, n_seeds, mean, low, high (95 % t interval over seeds)."""
    rows = []
    for (model, scenario), group in evals.groupby(["model", "scenario"]):
        for metric in metrics:
            if metric not in group:
                continue
            est = in_range(mean_ci(group[metric].to_numpy(dtype=float)), metric)
            rows.append({"model": model, "scenario": str(scenario), "metric": metric, "n_seeds": est.n,
                         "mean": est.point, "low": est.low, "high": est.high})
    return pd.DataFrame(rows, columns=["model", "scenario", "metric", "n_seeds", "mean", "low", "high"])


# The scenario the headline reads beside the mean over scenarios: the paper's middle mix (CV ratio 0.5),
# the same traffic as the training mix (conf/scenario/train.yaml).
HEADLINE_SCENARIO = "3"
HEADLINE_METRICS = ("episode_return", "collisions")


def headline(evals: pd.DataFrame, scenarios: list[str], scenario: str = HEADLINE_SCENARIO,
             metrics: tuple[str, ...] = HEADLINE_METRICS) -> pd.DataFrame:
    """One row per host: for each metric, the mean over seeds in `scenario` and the mean over `scenarios`
    (each seed averaged over them first), with their t intervals: columns `<metric>/<where>/<point|low|high|n>`
    with where = 'scenario' or 'mean'."""
    rows = []
    for model in ordered_models(evals["model"]):
        row: dict[str, object] = {"model": model}
        for metric in metrics:
            by_scenario = per_scenario(evals, model, metric, scenarios)
            for where, est in (("scenario", in_range(mean_ci(by_scenario.get(scenario, [])), metric)),
                               ("mean", in_range(stratified_mean_ci(by_scenario), metric))):
                for part in ("point", "low", "high", "n"):
                    row[f"{metric}/{where}/{part}"] = getattr(est, part)
        rows.append(row)
    return pd.DataFrame(rows)


def cell_text(mean: float, low: float, high: float, n: int, metric: str) -> str:
    """Mean on the first line, the CI (or why there is none) on the second."""
    if n == 0 or np.isnan(mean):
        return "-"
    if n < 2 or np.isnan(low):
        return f"{fmt(mean, metric)}\n(1 seed, no CI)"
    return f"{fmt(mean, metric)}\n[{fmt(low, metric)}, {fmt(high, metric)}]"


def wide(summary_table: pd.DataFrame, metric: str, scenarios: list[str] | None = None) -> pd.DataFrame:
    """Method x scenario grid of formatted cells for one metric; '-' where the store has no run."""
    part = summary_table[summary_table["metric"] == metric]
    models = ordered_models(part["model"])
    cols = scenarios or ordered_scenarios(part["scenario"])
    grid = pd.DataFrame("-", index=pd.Index(models, name="model"), columns=cols)
    for row in part.itertuples(index=False):
        if row.scenario in cols:
            grid.loc[row.model, row.scenario] = cell_text(row.mean, row.low, row.high, row.n_seeds, metric)
    return grid


def seed_counts(evals: pd.DataFrame, scenarios: list[str] | None = None) -> pd.DataFrame:
    """How many seeds each method x scenario cell holds (0 = missing)."""
    cols = scenarios or ordered_scenarios(evals["scenario"])
    counts = evals.groupby(["model", "scenario"])["seed"].nunique().unstack(fill_value=0)
    counts = counts.reindex(index=ordered_models(evals["model"]), columns=cols, fill_value=0)
    return counts.astype(int)


def aggregate(evals: pd.DataFrame, metric: str, scenarios: list[str],
              baseline: str = "proposed") -> pd.DataFrame:
    """Across-scenario summaries per method: the mean (each seed averaged over the scenarios, then the t
    interval over seeds), the IQM and P(baseline > method); the last two are points (no interval for them
    has been shown to cover at five seeds)."""
    rows = []
    base = per_scenario(evals, baseline, metric, scenarios)
    for model in ordered_models(evals["model"]):
        scores = per_scenario(evals, model, metric, scenarios)
        if not scores:
            continue
        mean = stratified_mean_ci(scores)
        poi = probability_of_improvement(base, scores) if model != baseline and base else NO_DATA
        rows.append({"model": model, "scenarios": len(scores), "min_seeds": mean.n,
                     "mean": mean.point, "mean_low": mean.low, "mean_high": mean.high,
                     "iqm": iqm(np.concatenate([s.to_numpy(float) for s in scores.values()])),
                     "p_improve": poi.point})
    return pd.DataFrame(rows)


# The bar a learned host clears on a seed when it drives better than the human-driven host there:
# more test return than that seed's human-driven host in the same scenario, with under this many
# collisions per episode (the human-driven host, under its safety layer, has none).
SAFE_COLLISIONS = 0.2
# What the close counts in a cell of the seed-by-seed comparison mean.
CLOSE_NOTE = (f"Close: a seed on which the host is safe (under {SAFE_COLLISIONS:g} collisions per episode) and its "
              "return margin over the human-driven host lies inside the test's own noise (the 95% bootstrap "
              "interval over the two hosts' test episodes covers zero), so a longer test of the same networks could "
              "decide it either way. 'k of n (c of them close)': c of the k winning seeds are close wins; 'l close "
              "loss(es)': seeds that lose by a margin inside that noise, not counted in k. Per seed in "
              "seed_margins_vs_human.csv.")


def seed_margins(evals: pd.DataFrame, episodes: pd.DataFrame | None = None, reference: str = "human",
                 max_collisions: float = SAFE_COLLISIONS) -> pd.DataFrame:
    """One row per (model, scenario, seed) that `reference` was tested on too: the model's test return
    and collisions, the reference's return, `margin` (their difference), `beating` (more return with
    under `max_collisions` collisions per episode) and, from `episodes` (one row per test episode), the
    margin's 95% test-noise interval `margin_low`/`margin_high` and `close`: the host is safe and the
    interval covers zero, so a longer test of the same networks could turn that seed's verdict either way.
    Empty without the reference."""
    columns = ["model", "scenario", "seed", "episode_return", "collisions", "ref_return", "margin",
               "margin_low", "margin_high", "beating", "close"]
    needed = {"model", "scenario", "seed", "episode_return", "collisions"}
    if evals.empty or not needed <= set(evals) or reference not in set(evals["model"]):
        return pd.DataFrame(columns=columns)
    cells = evals.groupby(["model", "scenario", "seed"])[["episode_return", "collisions"]].mean().reset_index()
    cells["scenario"] = cells["scenario"].astype(str)
    ref = cells[cells["model"] == reference].rename(columns={"episode_return": "ref_return"})
    paired = cells[cells["model"] != reference].merge(ref[["scenario", "seed", "ref_return"]], on=["scenario", "seed"])
    paired["margin"] = paired["episode_return"] - paired["ref_return"]
    paired["beating"] = (paired["margin"] > 0) & (paired["collisions"] < max_collisions)
    paired["margin_low"] = paired["margin_high"] = np.nan
    if episodes is not None and not episodes.empty and needed <= set(episodes):
        eps = episodes.assign(scenario=episodes["scenario"].astype(str))
        returns = {key: g["episode_return"].to_numpy(float) for key, g in eps.groupby(["model", "scenario", "seed"])}
        for i, row in paired.iterrows():
            mine = returns.get((row["model"], row["scenario"], row["seed"]))
            theirs = returns.get((reference, row["scenario"], row["seed"]))
            if mine is not None and theirs is not None:
                est = test_noise_ci(mine, theirs)
                paired.loc[i, ["margin_low", "margin_high"]] = [est.low, est.high]
    # Only a safe seed's verdict turns on its return, so only there can the test's noise on the return decide it.
    inside = (paired["margin_low"] <= 0) & (paired["margin_high"] >= 0)
    paired["close"] = (paired["collisions"] < max_collisions) & inside
    order = {m: i for i, m in enumerate(ordered_models(paired["model"]))}
    paired = paired.sort_values(["model", "scenario", "seed"],
                                key=lambda c: c.map(order) if c.name == "model" else c)
    return paired[columns].reset_index(drop=True)


def seeds_beating(evals: pd.DataFrame, reference: str = "human", scenarios: list[str] | None = None,
                  max_collisions: float = SAFE_COLLISIONS, episodes: pd.DataFrame | None = None) -> pd.DataFrame:
    """Long table, one row per (model, scenario) other than `reference`'s: `seeds`, those on which both the
    model and `reference` were tested, and `beating`, those on which the model's test return exceeds the
    reference's with under `max_collisions` collisions per episode. Empty without the reference. With
    `episodes`, also the seeds whose return margin lies inside the test's noise (`seed_margins`), split by
    side: `close_won` (counted in `beating`) and `close_lost` (not)."""
    margins = seed_margins(evals, episodes, reference, max_collisions)
    columns = ["model", "scenario", "seeds", "beating"] + (["close_won", "close_lost"] if episodes is not None else [])
    if margins.empty:
        return pd.DataFrame(columns=columns)
    margins = margins.assign(close_won=margins["close"] & margins["beating"],
                             close_lost=margins["close"] & ~margins["beating"])
    out = margins.groupby(["model", "scenario"], sort=False).agg(
        seeds=("seed", "nunique"), beating=("beating", "sum"), close_won=("close_won", "sum"),
        close_lost=("close_lost", "sum")).reset_index()
    if scenarios is not None:
        out = out[out["scenario"].isin(scenarios)]
    return out[columns].astype({c: int for c in columns[2:]}).reset_index(drop=True)


def beating_grid(beating: pd.DataFrame, scenarios: list[str]) -> pd.DataFrame:
    """Method x scenario cells 'k of n' from `seeds_beating`; '(c of them close)' where c of the k winning
    seeds win inside the test's noise, '(l close loss(es))' where l losing seeds lose inside it; '-' where a
    cell has no paired seed."""
    grid = pd.DataFrame("-", index=pd.Index(ordered_models(beating["model"]), name="model"), columns=scenarios)
    for row in beating.itertuples(index=False):
        if row.scenario in scenarios:
            won, lost = getattr(row, "close_won", 0), getattr(row, "close_lost", 0)
            close = [f"{won} of them close"] * bool(won) + [f"{lost} close loss{'es' * (lost != 1)}"] * bool(lost)
            grid.loc[row.model, row.scenario] = f"{row.beating} of {row.seeds}" + (f" ({'; '.join(close)})"
                                                                                    if close else "")
    return grid


def paper_table6() -> pd.DataFrame:
    table = PAPER_TABLE6.copy()
    table.index = [model_label(m, short=True) for m in table.index]
    return table


def write_csvs(summary_table: pd.DataFrame, out_dir: Path) -> list[Path]:
    """Machine-readable copies of the numbers the report typesets."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "test_summary.csv", out_dir / "paper_table6.csv"]
    summary_table.to_csv(paths[0], index=False)
    PAPER_TABLE6.to_csv(paths[1])
    return paths
