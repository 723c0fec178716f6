"""Crash anatomy: every host crash of the test episodes by what led to it, per host and scenario, and
what the safety layer refused the hosts that drive under it. Read from the episodes' event columns
(`hgm_repro.contracts.events`, the one rule); tests run before those columns existed did not record
them, and the section then says so."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from analysis.figures import save  # noqa: E402
from analysis.labels import SHORT_LABELS, model_label, ordered_models, ordered_scenarios  # noqa: E402
from analysis.sections import Section  # noqa: E402
from hgm_repro.contracts.events import (  # noqa: E402
    CRASH_KIND_LABELS,
    CRASH_KINDS,
    EPISODE_EVENTS,
    LANE_CHANGE_CRASH_DECISIONS,
    LANE_CHANGE_REQUESTS,
    REFUSED_BY_GAP,
    REFUSED_BY_PARITY,
    crash_kind,
)

TITLE = "Crash anatomy"
KIND_WORDS = {"lane_change": "in a lane change", "rear_end": "rear-ends", "hit_from_behind": "hit from behind",
              "other": "other"}
KIND_COLOURS = {"lane_change": "#d1495b", "rear_end": "#1b6ca8", "hit_from_behind": "#e08a1e", "other": "#888888"}
NOT_RECORDED = ("The crash anatomy is not recorded in these runs: their tests predate the per-episode event columns "
                "(who ran into whom, lane changes before the crash). Test the trainings again to get it.")


def recorded(episodes: pd.DataFrame) -> pd.DataFrame:
    """The test episodes that carry the event columns (a bundle combined from old and new tests has them
    missing on the old rows)."""
    if episodes is None or episodes.empty or not all(c in episodes.columns for c in EPISODE_EVENTS):
        return pd.DataFrame()
    return episodes[episodes[list(EPISODE_EVENTS)].notna().all(axis=1)]


def anatomy(episodes: pd.DataFrame) -> pd.DataFrame:
    """One row per host and scenario: `episodes`, `crashes`, `crashes_per_episode`, and per kind its
    count (`<kind>`) and share of the crashes (`<kind>_share`); then the lane-change requests, those the
    gaps and the parity alone refused (counts, requests per episode, and shares of the requests). Empty
    when not recorded."""
    rows = recorded(episodes)
    if rows.empty:
        return pd.DataFrame()
    rows = rows.assign(kind=crash_kind(rows))
    out = []
    for (model, scenario), group in rows.groupby(["model", "scenario"]):
        crashes = int(group["kind"].notna().sum())
        requests = float(group[LANE_CHANGE_REQUESTS].sum())
        row: dict[str, object] = {"model": model, "scenario": str(scenario), "episodes": len(group),
                                  "crashes": crashes, "crashes_per_episode": crashes / len(group)}
        for kind in CRASH_KINDS:
            count = int((group["kind"] == kind).sum())
            row[kind] = count
            row[f"{kind}_share"] = count / crashes if crashes else float("nan")
        gap, parity = float(group[REFUSED_BY_GAP].sum()), float(group[REFUSED_BY_PARITY].sum())
        row.update(lane_change_requests=requests, refused_gap=gap, refused_parity=parity,
                   lane_change_requests_per_episode=requests / len(group),
                   refused_gap_share=gap / requests if requests else float("nan"),
                   refused_parity_share=parity / requests if requests else float("nan"))
        out.append(row)
    table = pd.DataFrame(out)
    order = {m: i for i, m in enumerate(ordered_models(table["model"]))}
    scen = {s: i for i, s in enumerate(ordered_scenarios(table["scenario"]))}
    return table.sort_values(["model", "scenario"], key=lambda c: c.map(order if c.name == "model" else scen),
                             ignore_index=True)


def pooled(table: pd.DataFrame) -> pd.DataFrame:
    """`anatomy` summed over scenarios: one row per host."""
    counts = table.groupby("model", sort=False)[["episodes", "crashes", *CRASH_KINDS]].sum().reset_index()
    counts["crashes_per_episode"] = counts["crashes"] / counts["episodes"]
    return counts


def seed_shares(episodes: pd.DataFrame) -> pd.DataFrame:
    """One row per host and seed that crashed (all scenarios pooled): `crashes` and each kind's share."""
    rows = recorded(episodes)
    if rows.empty or "seed" not in rows:
        return pd.DataFrame(columns=["model", "seed", "crashes", *(f"{k}_share" for k in CRASH_KINDS)])
    kinds = rows.assign(kind=crash_kind(rows)).dropna(subset=["kind"])
    out = kinds.groupby(["model", "seed"])["kind"].value_counts(normalize=True).unstack(fill_value=0.0)
    out = out.reindex(columns=list(CRASH_KINDS), fill_value=0.0).add_suffix("_share")
    out.insert(0, "crashes", kinds.groupby(["model", "seed"]).size())
    return out.reset_index()


def host_sentences(table: pd.DataFrame, episodes: pd.DataFrame) -> list[str]:
    """Per host that crashed: its crashes over all scenarios by kind, and how far the seeds differ in the
    share of lane-change crashes (a seed that never changes lanes crashes otherwise)."""
    shares = seed_shares(episodes)
    out = []
    # Every scenario of a host that crashed, its crash-free ones too: they are episodes of its rate.
    crashed = table[table["model"].isin(set(table.loc[table["crashes"] > 0, "model"]))]
    for _, r in pooled(crashed).iterrows():
        kinds = ", ".join(f"{int(r[k])} {KIND_WORDS[k]} ({r[k] / r['crashes']:.0%})"
                          for k in CRASH_KINDS if r[k])
        text = (f"{model_label(r['model'], short=True)}: {int(r['crashes'])} crashes in {int(r['episodes'])} test "
                f"episodes ({r['crashes_per_episode']:.3f} per episode): {kinds}")
        mine = shares[shares["model"] == r["model"]].sort_values("lane_change_share")
        if len(mine) > 1:
            low, high = mine.iloc[0], mine.iloc[-1]
            text += (f". By seed, lane changes are {low['lane_change_share']:.0%} (seed {low['seed']}) to "
                     f"{high['lane_change_share']:.0%} (seed {high['seed']}) of its crashes")
        out.append(text + ".")
    return out


def figure(table: pd.DataFrame, stem: Path) -> dict[str, Path] | None:
    """Crashes per test episode by kind, stacked, one bar per host that crashed (all scenarios pooled),
    beside one panel per scenario."""
    crashed = table[table["crashes"] > 0]
    if crashed.empty:
        return None
    scenarios = ordered_scenarios(crashed["scenario"])
    fig, axes = plt.subplots(1, 1 + len(scenarios), figsize=(3.2 + 2.2 * len(scenarios), 3.6), sharey=True,
                             gridspec_kw={"width_ratios": [1.5] + [1] * len(scenarios)})
    hosts = table[table["model"].isin(set(crashed["model"]))]  # their crash-free scenarios count in the pool
    panels = [("all scenarios", pooled(hosts))] + [(f"scenario {s}", crashed[crashed["scenario"] == s])
                                                     for s in scenarios]
    for ax, (title, part) in zip(axes, panels, strict=True):
        models = ordered_models(part["model"])
        part = part.set_index("model").loc[models]
        bottom = pd.Series(0.0, index=models)
        for kind in CRASH_KINDS:
            rate = part[kind] / part["episodes"]
            ax.bar(range(len(models)), rate, bottom=bottom, color=KIND_COLOURS[kind],
                   label=CRASH_KIND_LABELS[kind] if ax is axes[0] else None)
            bottom = bottom + rate
        ax.set_xticks(range(len(models)), [SHORT_LABELS.get(m, m) for m in models], rotation=35, ha="right",
                      fontsize=8)
        ax.set_title(title, fontsize=10)
    axes[0].set_ylabel("crashes per test episode")
    fig.legend(loc="upper center", ncol=len(CRASH_KINDS), fontsize=8, bbox_to_anchor=(0.5, 1.08), frameon=False)
    fig.tight_layout()
    return save(fig, stem)


def _count_share(count: int, share: float) -> str:
    return "0" if count == 0 else f"{count} ({share:.0%})"


def anatomy_rows(table: pd.DataFrame) -> list[list[str]]:
    """The hosts that crashed, per scenario: crashes per episode, then each kind's count (share of crashes)."""
    head = ["Host", "Scenario", "Episodes", "Crashes per episode", *[k.replace("_", " ") for k in CRASH_KINDS]]
    rows = [head]
    for _, r in table[table["crashes"] > 0].iterrows():
        rows.append([SHORT_LABELS.get(r["model"], r["model"]), r["scenario"], str(r["episodes"]),
                     f"{r['crashes_per_episode']:.3f}", *[_count_share(r[k], r[f"{k}_share"]) for k in CRASH_KINDS]])
    return rows


def refusal_rows(table: pd.DataFrame) -> list[list[str]]:
    """Hosts the layer refused anything (they drive under it), pooled over scenarios."""
    rows = [["Host", "Lane-change requests per episode", "Refused by the gaps", "Refused by the parity alone"]]
    for model in ordered_models(table["model"]):
        part = table[table["model"] == model]
        requests, gap, parity = (part[c].sum() for c in ("lane_change_requests", "refused_gap", "refused_parity"))
        if requests and gap + parity > 0:
            rows.append([model_label(model), f"{requests / part['episodes'].sum():.2f}", f"{gap / requests:.0%}",
                         f"{parity / requests:.0%}"])
    return rows


def section(episodes: pd.DataFrame, out_dir: Path) -> tuple[Section, pd.DataFrame, dict[str, Path] | None]:
    """The report's crash-anatomy section, its table (also written as crash_anatomy.csv) and figure."""
    out = Section(TITLE)
    table = anatomy(episodes)
    if table.empty:
        return out.para(NOT_RECORDED), table, None
    out.para(f"Each host crash of the test episodes (an episode ends at its first) by what led to it: a lane change "
             f"the host began in the last {LANE_CHANGE_CRASH_DECISIONS} decisions (its lane change takes 7, and its "
             "body reaches a car beside it after 4); a rear-end, the host running into the vehicle ahead in its own "
             "lane; hit from behind, a vehicle in the host's lane running into it; other (a vehicle cutting in or "
             "out, both at once). Counts over all seeds' test episodes, with the share of the host's crashes.")
    never = [model_label(m) for m in ordered_models(table["model"])
             if table.loc[table["model"] == m, "crashes"].sum() == 0]
    if never:
        out.para("No crash in any test episode: " + ", ".join(never) + ".")
    old = episodes.loc[episodes.index.difference(recorded(episodes).index), "model"]
    if not old.empty:
        out.para("Not recorded for " + ", ".join(model_label(m) for m in ordered_models(old.unique())) + " (in "
                 f"{len(old)} of the {len(episodes)} test episodes): those tests predate the per-episode event "
                 "columns, and their crashes are not counted here. Test the trainings again to add them.")
    for sentence in host_sentences(table, episodes):
        out.para(sentence)
    paths = figure(table, out_dir / "fig_crash_anatomy")
    if paths is not None:
        out.figure(paths["png"], "Crashes per test episode by what led to them, per host (all scenarios, then each "
                                 "scenario).")
    if len(anatomy_rows(table)) > 1:
        out.table(anatomy_rows(table), widths=[1.6, 0.8, 0.8, 1.0, 1.1, 1.1, 1.1, 1.1])
    refusals = refusal_rows(table)
    if len(refusals) > 1:
        out.para("What the safety layer refused the hosts that drive under it. A lane-change request is a lane action "
                 "while no lane change is under way and the lane exists; the layer starts it only when the gaps in "
                 "the target lane allow it and the decision's parity does (left on even decisions, right on odd "
                 "ones, so that two guarded drivers never merge into one lane at once). A learned host cannot see "
                 "the parity: the last column is what that costs it.")
        out.table(refusals, widths=[2.6, 1.2, 1.0, 1.0])
    table.to_csv(out_dir / "crash_anatomy.csv", index=False, float_format="%.6g")
    return out, table, paths
