"""The scale ladder as a picture: how each method's scenario-3 return and collisions move from rung to rung.

One panel per metric, the rungs along x (lowest first), each method a column of its seeds' values (one dot per
seed) with the mean over seeds and, from `COVERAGE_SEEDS` seeds on, its 95 % t interval: the numbers of the ladder's
tables (`method_rows`). Below that count the interval's coverage is not measured (the tables print no interval
either), and a t interval on one degree of freedom is wide enough to flatten every other column on the axis, so
the seeds and their mean stand alone. The
human-driven host does not train: its mean and interval are a grey band across every rung. A rung or method not
run yet is left empty and says so, so that a gap is never read as a zero.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from analysis.figures import save, use_style
from analysis.labels import LEARNED, METRIC_LABELS, PALETTE, model_label
from analysis.rung import Rung, absence
from analysis.stats import COVERAGE_SEEDS
from analysis.tables import HEADLINE_SCENARIO, per_scenario

METRICS = ("episode_return", "collisions")
WIDTH = 0.22  # the distance between two methods' columns within a rung


def _tick(name: str, label: str) -> str:
    # "the paper's steps (1M steps, Table 4's learner, 36x36x2)" -> "paper_steps\n1M steps, Table 4's learner, ..."
    inside = label[label.find("(") + 1:label.rfind(")")] if "(" in label else label
    return f"{name}\n" + inside.replace(", ", "\n", 1)


def figure(rungs: list[Rung], numbers: pd.DataFrame, reference: str, stem: Path,
           under_way: set[tuple[str, str]] | frozenset[tuple[str, str]] = frozenset()) -> dict[str, Path] | None:
    """`rungs` (lowest first) and their `numbers` (`method_rows` of each, with `rung`;
    `reference` the host that does not train; `under_way` the (rung, model) pairs with a stopped training): the
    ladder figure saved under `stem`, or None while no rung has a learned host's run."""
    if not any(r.ran for r in rungs):
        return None
    return save(draw(rungs, numbers, reference, under_way), stem)


def draw(rungs: list[Rung], numbers: pd.DataFrame, reference: str,
         under_way: set[tuple[str, str]] | frozenset[tuple[str, str]] = frozenset()) -> plt.Figure:
    """The ladder figure, not saved: per panel, each method's mean is a line with a diamond marker (`gid`
    `mean/RUNG/MODEL`), its seeds a scatter (`gid` `seeds/RUNG/MODEL`) and, from `COVERAGE_SEEDS` seeds, its
    interval an error bar (`gid` `interval/RUNG/MODEL`). A method with no seed tested on a rung is marked
    "under way" where one of its trainings there was stopped part-way (`under_way`), else "not run"."""
    use_style()
    fig, axes = plt.subplots(1, len(METRICS), figsize=(10.0, 4.2))
    rng = np.random.default_rng(0)  # the dots' sideways jitter only, so that equal values stay apart
    for ax, metric in zip(axes, METRICS, strict=True):
        tested = numbers[(numbers["model"] == reference) & (numbers["seeds"] > 0)]
        if not tested.empty:
            ref = tested.iloc[0]
            ax.axhline(ref[f"{metric}/point"], color=PALETTE[reference], linestyle="--", linewidth=1.2,
                       gid=f"reference/{reference}")
            if np.isfinite(ref[f"{metric}/low"]):
                ax.axhspan(ref[f"{metric}/low"], ref[f"{metric}/high"], color=PALETTE[reference], alpha=0.12,
                           linewidth=0)
        for x, r in enumerate(rungs):
            rows = numbers[numbers["rung"] == r.name].set_index("model")
            for k, model in enumerate(LEARNED):
                at = x + (k - (len(LEARNED) - 1) / 2) * WIDTH
                row = rows.loc[model] if model in rows.index else None
                if row is None or not row["seeds"]:
                    mark = absence(r.name, under_way, model)
                    ax.text(at, 0.02, mark, rotation=90, ha="center", va="bottom", fontsize=7, color="0.45",
                            transform=ax.get_xaxis_transform())
                    continue
                seeds = per_scenario(r.evals, model, metric, [HEADLINE_SCENARIO]).get(HEADLINE_SCENARIO)
                if seeds is not None and len(seeds):
                    ax.scatter(at + rng.uniform(-0.04, 0.04, len(seeds)), seeds.to_numpy(), s=14,
                               color=PALETTE[model], alpha=0.45, linewidths=0, zorder=2,
                               gid=f"seeds/{r.name}/{model}")
                point, low, high = (row[f"{metric}/{p}"] for p in ("point", "low", "high"))
                if row["seeds"] >= COVERAGE_SEEDS and np.isfinite(low):
                    bar = ax.errorbar(at, point, yerr=[[point - low], [high - point]], fmt="none",
                                      ecolor=PALETTE[model], elinewidth=1.6, capsize=4, zorder=3)
                    for part in bar.get_children():
                        part.set_gid(f"interval/{r.name}/{model}")
                ax.plot(at, point, marker="D", markersize=6, color=PALETTE[model], markeredgecolor="white", zorder=4,
                        gid=f"mean/{r.name}/{model}")
                ax.annotate(f"n={int(row['seeds'])}", (at, 0.0), xycoords=("data", "axes fraction"),
                            xytext=(0, -2), textcoords="offset points", ha="center", va="top", fontsize=6.5,
                            color="0.35")
        ax.set_xticks(range(len(rungs)), [_tick(r.name, r.label) for r in rungs], fontsize=7.5)
        ax.tick_params(axis="x", pad=12)  # room for the seed counts under each column
        ax.set_xlim(-0.5, len(rungs) - 0.5)
        ax.grid(axis="x", visible=False)  # a rung's middle line would run through its middle method's column
        ax.set_title(f"{METRIC_LABELS.get(metric, metric)}, scenario {HEADLINE_SCENARIO}", fontsize=10)
    axes[1].set_ylim(bottom=-0.02)
    handles = [plt.Line2D([], [], color=PALETTE[m], marker="D", linestyle="none", label=model_label(m))
               for m in LEARNED]
    handles.append(plt.Line2D([], [], color=PALETTE[reference], linestyle="--",
                              label=f"{model_label(reference)} (does not train: every rung)"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), frameon=False, fontsize=8,
               bbox_to_anchor=(0.5, -0.03))
    fig.suptitle(f"How the answer moves with scale: seeds (dots), mean and, from {COVERAGE_SEEDS} seeds, "
                 "95 % t interval", fontweight="bold", fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return fig
