"""results.md: the test table beside the paper's Table 6, the safety numbers beside it, and the
verdict on each claim, as Markdown for docs/results/, which the README links (report.pdf holds the rest:
curves, configs, every metric)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from analysis.claims import ClaimResult, verdict_sentence
from analysis.labels import METRIC_LABELS, PROBES, SCENARIOS, model_label, ordered_models
from analysis.report import HEADLINE_NOTE, fmt_estimate, headline_rows
from analysis.scale import is_smoke, scale_lines
from analysis.sections import Section, markdown_lines
from analysis.stats import coverage_text
from analysis.tables import CLOSE_NOTE, PAPER_TABLE6, SAFE_COLLISIONS, beating_grid, headline

# The metrics shown beside the return: what a test score alone hides (a fast host that crashes).
SIDE_METRICS = ("collisions", "avg_speed_kmh", "dangerous_actions")
FIGURES = (("fig5_speed", "Fig. 5: training speed"), ("fig6_lane_changes", "Fig. 6: training lane changes"),
           ("fig7_overtakes", "Fig. 7: training overtakes"), ("fig_test_results", "Test results per scenario"))


def _grid(summary: pd.DataFrame, metric: str, scenarios: list[str], paper: bool) -> list[str]:
    part = summary[summary["metric"] == metric]
    rows = {(r["model"], r["scenario"]): r for _, r in part.iterrows()}
    head = ["Method", "Seeds", *[f"Scenario {s}" for s in scenarios]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * 2 + "---:|" * len(scenarios)]
    for model in ordered_models(part["model"]):
        seeds = sorted({int(rows[(model, s)]["n_seeds"]) for s in scenarios if (model, s) in rows})
        cells = []
        for s in scenarios:
            row = rows.get((model, s))
            text = "-" if row is None else fmt_estimate(row["mean"], row["low"], row["high"], int(row["n_seeds"]),
                                                         metric)
            if paper and model in PAPER_TABLE6.index and s in PAPER_TABLE6.columns:
                text += f" (paper {PAPER_TABLE6.loc[model, s]})"
            cells.append(text)
        seed_text = "/".join(map(str, seeds)) or "0"
        lines.append(f"| {model_label(model, short=True)} | {seed_text} | " + " | ".join(cells) + " |")
    return lines


def beating_lines(beating: pd.DataFrame, scenarios: list[str]) -> list[str]:
    """The seed-by-seed comparison with the human-driven host, as a Markdown section (none without it)."""
    if beating.empty:
        return []
    grid = beating_grid(beating, scenarios)
    lines = [f"## Seeds on which a host beats the human-driven host (more return, under {SAFE_COLLISIONS:g} "
             "collisions per episode)", "",
             "Each seed's test return is set against the human-driven host's on the same seed and scenario (the "
             "same traffic); a mean can hide that only some seeds drive better.", "",
             "| Method | " + " | ".join(f"Scenario {s}" for s in grid.columns) + " |",
             "|---|" + "---:|" * len(grid.columns)]
    for model, row in grid.iterrows():
        lines.append(f"| {model_label(model, short=True)} | " + " | ".join(row) + " |")
    if "close" in beating:
        lines += ["", CLOSE_NOTE]
    return [*lines, ""]


def headline_lines(evals: pd.DataFrame, scenarios: list[str]) -> list[str]:
    """The headline table (return and collisions per host, scenario 3 and the mean of scenarios) in Markdown."""
    rows = headline_rows(headline(evals[~evals["model"].isin(PROBES)], scenarios))
    out = ["| " + " | ".join(rows[0]) + " |", "|---|---:|" + "---:|" * (len(rows[0]) - 2)]
    out += ["| " + " | ".join(row) + " |" for row in rows[1:]]
    return out


def results_markdown(summary: pd.DataFrame, claims: list[ClaimResult], configs: dict[str, str],
                     evals: pd.DataFrame, commits: list[str], figures: dict[str, dict[str, Path]],
                     out_dir: Path, beating: pd.DataFrame | None = None,
                     sections: list[Section] | None = None, ladder_lines: list[str] | None = None) -> str:
    """The Markdown text; figure links are relative to `out_dir`, where results.md is written. `ladder_lines`:
    what the scale ladder's other rungs found (`analysis.ladder.page_one_lines`), said with the scale."""
    scenarios = [s for s in SCENARIOS if s in set(summary["scenario"])] \
        or sorted(set(summary["scenario"]))
    banner = ["**Smoke run: not a result.** The `smoke` preset trains for seconds to prove that the pipeline "
              "runs; its numbers and verdicts mean nothing.", ""] if is_smoke(configs) else []
    lines = ["# Results", "", *banner,
             "## What each host earns and how often it crashes", "", *headline_lines(evals, scenarios), "",
             HEADLINE_NOTE, "",
             "## The paper's claims in one line each", "",
             *[f"{c.number}. {c.statement} **{c.verdict}**: {verdict_sentence(c)}" for c in claims], "",
             coverage_text(), "",
             "## Scale", "", *[f"- {line}" for line in [*scale_lines(configs, evals), *(ladder_lines or [])]], "",
             f"Runs from commit{'s' if len(commits) != 1 else ''} {', '.join(c[:10] for c in commits) or 'unknown'}. "
             "Every other table: mean over seeds [95% t interval over seeds].", "",
             "## Test return per episode (the paper's Table 6; its numbers in parentheses)", "",
             *_grid(summary, "episode_return", scenarios, paper=True), "",
             "The paper does not say what its test score sums; ours is the mean return of a test episode under "
             "Table 2's rewards (an episode ends at its time limit or at the host's first collision), so only the "
             "order of the methods compares.", ""]
    for metric in SIDE_METRICS:
        if metric in set(summary["metric"]):
            lines += [f"## {METRIC_LABELS[metric]}", "",
                      *_grid(summary, metric, scenarios, paper=False), ""]
    lines += beating_lines(beating if beating is not None else pd.DataFrame(), scenarios)
    lines += ["## The paper's claims: the evidence", "", "| # | Claim | Verdict | Evidence |", "|---|---|---|---|"]
    for claim in claims:
        evidence = "; ".join(c.text() for c in claim.comparisons).replace("|", "/")
        lines.append(f"| {claim.number} | {claim.statement} | **{claim.verdict}** | {evidence} |")
    for extra in sections or []:
        lines += ["", *markdown_lines(extra, out_dir)]
    shown = [(name, label) for name, label in FIGURES if name in figures]
    if shown:
        lines += ["", "## Figures", ""]
        for name, label in shown:
            lines += [f"![{label}]({Path(figures[name]['png']).relative_to(out_dir)})", ""]
    return "\n".join(lines).rstrip() + "\n"
