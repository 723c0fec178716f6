"""The paper's Figs. 5-7 (training curves per method) and a test-results figure, from our runs."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display on the machines this runs on

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import seaborn as sns  # noqa: E402

from analysis.curves import bin_curves  # noqa: E402
from analysis.labels import (  # noqa: E402
    LEARNED,
    METRIC_LABELS,
    PALETTE,
    PROBES,
    REFERENCE_HOSTS,
    SCENARIOS,
    model_label,
    ordered_models,
    ordered_scenarios,
)
from analysis.scenarios import PAPER_CV_RATIO  # noqa: E402
from analysis.stats import t_interval  # noqa: E402

FORMATS = ("png", "pdf", "svg")
TRAINING_FIGURES = {  # file stem -> (train metric, matching eval metric for reference lines, paper figure)
    "fig5_speed": ("avg_speed_kmh", "avg_speed_kmh", "Fig. 5"),
    "fig6_lane_changes": ("lane_changes", "lane_changes", "Fig. 6"),
    "fig7_overtakes": ("overtakes", "overtakes", "Fig. 7"),
}
TEST_METRICS = ("episode_return", "avg_speed_kmh", "lane_changes", "overtakes", "collisions",
                "dangerous_actions")


def use_style() -> None:
    # Sized for a 16 cm wide figure in an A4 report: 9-10 pt text stays readable when printed.
    sns.set_theme(context="paper", style="whitegrid", font_scale=1.15)
    plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 200, "axes.titleweight": "bold"})


def save(fig: plt.Figure, stem: Path, formats: tuple[str, ...] = FORMATS) -> dict[str, Path]:
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = {}
    for ext in formats:
        path = stem.with_suffix(f".{ext}")
        fig.savefig(path, bbox_inches="tight")
        paths[ext] = path
    plt.close(fig)
    return paths


def reference_levels(evals: pd.DataFrame, metric: str) -> dict[str, tuple[float, str]]:
    """Eval mean of each non-learning host, in the traffic the learners trained in where possible.

    The training mix (CV 0.5, AHV 0.25, CHV 0.25) is scenario 3's mix, so scenario 'train' is
    preferred, then '3', then the mean over whatever scenarios the host was evaluated in.
    """
    levels = {}
    for host in REFERENCE_HOSTS:
        rows = evals[(evals["model"] == host) & evals[metric].notna()] if metric in evals else evals.iloc[:0]
        if rows.empty:
            continue
        for scenario, where in (("train", "training traffic"), ("3", "scenario 3")):
            sel = rows[rows["scenario"] == scenario]
            if not sel.empty:
                levels[host] = (float(sel[metric].mean()), where)
                break
        else:
            levels[host] = (float(rows.groupby("scenario")[metric].mean().mean()), "mean over test scenarios")
    return levels


def t_band(values: pd.Series) -> tuple[float, float]:
    """The 95 % Student-t interval over seeds as a seaborn error bar (the report's one interval method)."""
    arr = np.asarray(values, dtype=float)
    arr = arr[np.isfinite(arr)]
    if arr.size < 2:
        return (np.nan, np.nan)
    low, high = t_interval(arr[None, :])
    return float(low[0]), float(high[0])


def _curve_panel(ax: plt.Axes, binned: pd.DataFrame, models: list[str], evals: pd.DataFrame,
                 eval_metric: str) -> None:
    seeds = binned.groupby("model")["seed"].nunique()
    labels = {m: f"{model_label(m)} ({seeds[m]} seed{'s' if seeds[m] != 1 else ''})" for m in models}
    part = binned[binned["model"].isin(models)].assign(label=lambda f: f["model"].map(labels))
    palette = {labels[m]: PALETTE.get(m) or f"C{i}" for i, m in enumerate(models)}
    sns.lineplot(data=part, x="step", y="value", hue="label", hue_order=[labels[m] for m in models],
                 palette=palette, errorbar=t_band, ax=ax, linewidth=1.8)
    for host, (level, where) in reference_levels(evals, eval_metric).items():
        ax.axhline(level, color=PALETTE[host], linestyle="--", linewidth=1.3,
                   label=f"{model_label(host)} (eval, {where})")
    ax.set_xlim(0, part["step"].max())
    ax.set_xlabel("Environment steps", labelpad=1)
    ax.xaxis.set_major_formatter(matplotlib.ticker.EngFormatter(sep=""))


def training_figure(curves: pd.DataFrame, evals: pd.DataFrame, stem: Path) -> dict[str, Path] | None:
    """One of Figs. 5-7: mean over seeds per method with a 95 % t band, hosts as dashed lines. The paper's
    three methods fill the left panel over their own steps; a variant (another model or budget) gets a
    panel of its own, beside Proposed, so that a longer training does not squeeze the paper's x axis."""
    metric, eval_metric, paper_fig = TRAINING_FIGURES[stem.name]
    binned = bin_curves(curves, metric)
    if binned.empty:
        return None
    use_style()
    models = ordered_models(binned["model"])
    paper = [m for m in models if m in LEARNED]
    variants = [m for m in models if m not in LEARNED]
    panels = [p for p in (paper, (["proposed"] if "proposed" in paper else []) + variants if variants else [])
              if p]
    fig, axes = plt.subplots(1, len(panels), figsize=(7.0 if len(panels) == 1 else 11.0, 4.8), squeeze=False,
                             sharey=True, gridspec_kw={"width_ratios": [1.0] * len(panels)})
    titles = ["The paper's three methods", "Variants beside Proposed (not the paper's)"]
    for ax, group, title in zip(axes[0], panels, titles if paper else titles[1:], strict=False):
        _curve_panel(ax, binned, group, evals, eval_metric)
        ax.set_title(title if len(panels) > 1 else "", fontsize=10)
        ax.set_ylabel(METRIC_LABELS.get(metric, metric))
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=1 if len(panels) > 1 else 2,
                  frameon=False, fontsize=8)
    fig.suptitle(f"{METRIC_LABELS.get(metric, metric)} during training (cf. paper {paper_fig})", fontweight="bold")
    fig.tight_layout()
    return save(fig, stem)


def test_figure(evals: pd.DataFrame, stem: Path) -> dict[str, Path] | None:
    """Mean and 95 % CI over seeds of each test metric per scenario (x = CV ratio), one line per method."""
    data = evals[evals["scenario"].astype(str).isin(SCENARIOS) & ~evals["model"].isin(PROBES)]
    if data.empty:
        return None
    use_style()
    cv = data["cv_ratio"] if "cv_ratio" in data else data["scenario"].astype(str).map(PAPER_CV_RATIO)
    data = data.assign(cv=cv)
    models = ordered_models(data["model"])
    fig, axes = plt.subplots(2, 3, figsize=(10.0, 6.2), sharex=True)
    for ax, metric in zip(axes.ravel(), TEST_METRICS, strict=True):
        part = data[data[metric].notna()] if metric in data else data.iloc[:0]
        if part.empty:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        else:
            sns.pointplot(data=part, x="cv", y=metric, hue="model", hue_order=models,
                          palette={m: PALETTE.get(m, "black") for m in models}, errorbar=t_band,
                          dodge=0.35 if len(models) > 1 else False,  # one method: no dodge
                          markersize=4, linewidth=1.3, capsize=0.08,
                          native_scale=False, ax=ax, legend=False)
        ax.set_title(METRIC_LABELS.get(metric, metric), fontsize=10)
        ax.set_xlabel("CV ratio (scenario 1..5)")
        ax.set_ylabel("")
    handles = [plt.Line2D([], [], color=PALETTE.get(m, "black"), marker="o", label=model_label(m))
               for m in models]
    columns = min(len(models), 3)
    fig.legend(handles=handles, loc="lower center", ncol=columns, frameon=False, bbox_to_anchor=(0.5, 0.0))
    fig.suptitle("Test results per scenario: mean over seeds, 95 % t interval over seeds", fontweight="bold")
    # The panels end above the legend's rows, so that the lowest x labels stay clear of it however many hosts.
    fig.tight_layout(rect=(0, 0.01 + 0.036 * -(-len(models) // columns), 1, 1))
    return save(fig, stem)


def make_figures(curves: pd.DataFrame, evals: pd.DataFrame, out_dir: Path) -> dict[str, dict[str, Path]]:
    """All figures; a figure whose data is missing is left out of the returned dict."""
    made = {}
    learned_curves = curves[curves["model"].isin(LEARNED) | ~curves["model"].isin(REFERENCE_HOSTS)]
    for name in TRAINING_FIGURES:
        paths = training_figure(learned_curves, evals, out_dir / name)
        if paths:
            made[name] = paths
    paths = test_figure(evals, out_dir / "fig_test_results")
    if paths:
        made["fig_test_results"] = paths
    return made


def scenarios_present(evals: pd.DataFrame) -> list[str]:
    return [s for s in ordered_scenarios(evals["scenario"]) if s in SCENARIOS]


def image_variance(path: Path) -> float:
    """Pixel variance of a saved figure: 0 means a blank image."""
    from PIL import Image

    return float(np.asarray(Image.open(path).convert("L"), dtype=float).var())
