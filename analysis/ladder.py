"""The scale ladder: the same comparison at each rung of the paper's scale that this CPU can reach.

A rung is an experiment preset (the evaluation runs' `experiment.name`, evals' `experiment` column). Its
learned hosts were trained and tested with that preset; the human-driven host does not train, so its runs
(the same seeds in the same scenarios, hence the same test traffic) stand beside every rung. Each rung is
judged on its own runs alone: the scenario-3 return and collisions, the seeds that beat the human-driven
host, and each of the paper's claims by the claims section's rule. Only the paper's three methods climb the
ladder; a variant (the enriched HGM, a guarded host) is left out.

The report's other pages read one preset per model (`analysis.load.main_experiments`); `main_view` cuts a
store down to that, so that the rungs of one model are never pooled as if they were more seeds.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pandas as pd

from analysis import ladder_figure
from analysis.claims import CLAIMS
from analysis.costs import hours_trained
from analysis.labels import LEARNED, METRIC_LABELS, NOT_RUN, UNDER_WAY, fmt, listed, model_label
from analysis.load import StoreData, at_main_experiments, main_experiments, no_stopped
from analysis.report import fmt_estimate
from analysis.rung import Rung, absence
from analysis.sections import Section
from analysis.stats import COVERAGE_SEEDS, difference_ci
from analysis.tables import (
    HEADLINE_METRICS,
    HEADLINE_SCENARIO,
    SAFE_COLLISIONS,
    beating_grid,
    headline,
    per_scenario,
    seeds_beating,
)

TITLE = "Scale ladder"
# The rungs, lowest first: each preset and what it keeps of the paper's scale (conf/experiment/*.yaml).
RUNGS = {
    "quick": "CPU preset (80k steps, 36x36x2)",
    "paper_steps": "the paper's steps (1M steps, Table 4's learner, 36x36x2)",
    "paper_pixels": "the paper's pixels (160k steps, 84x84x4)",
}
REFERENCE = "human"  # does not train: its runs stand beside every rung
SCENARIOS = [HEADLINE_SCENARIO]  # the training traffic's mix
# How a rung's host drives (mean over seeds, scenario 3): a return or a crash rate alone does not say whether the
# host crawls, races into its leader or weaves.
DRIVING = ("avg_speed_kmh", "lane_changes")
FIGURE = "fig_scale_ladder"
BASE = "quick"  # the lowest rung: each higher rung is read against it, seed by seed
SHIFT_METRICS = (*HEADLINE_METRICS, *DRIVING)


def _reference_rows(evals: pd.DataFrame, rung: str) -> pd.DataFrame:
    """The human-driven host's runs for `rung`: its own runs at that preset if it has any, else those of its
    main experiment (one run per seed and scenario either way)."""
    rows = evals[evals["model"] == REFERENCE]
    if rows.empty or rung in set(rows["experiment"]):
        return rows[rows["experiment"] == rung]
    return rows[rows["experiment"] == main_experiments(rows)[REFERENCE]]


def rung(evals: pd.DataFrame, curves: pd.DataFrame, episodes: pd.DataFrame, name: str,
         runs: pd.DataFrame | None = None) -> Rung:
    """The runs of rung `name` (evals with the `experiment` column; curves, episodes and runs as `StoreData`
    holds them): the learned methods' training curves are those of the trainings its evaluation runs tested."""
    learned = evals[evals["model"].isin(LEARNED) & (evals["experiment"] == name)]
    rows = pd.concat([learned, _reference_rows(evals, name)], ignore_index=True)
    keys = set(learned["train_key"].dropna())
    rung_curves = curves[curves["model"].isin(LEARNED) & curves["train_key"].isin(keys)] if not curves.empty \
        else curves
    rung_episodes = episodes[episodes["run_id"].isin(set(rows["run_id"]))] if "run_id" in episodes else episodes
    return Rung(name, RUNGS.get(name, name), rows, rung_curves.reset_index(drop=True),
                rung_episodes.reset_index(drop=True), runs)


def rungs(evals: pd.DataFrame, curves: pd.DataFrame, episodes: pd.DataFrame,
          runs: pd.DataFrame | None = None) -> list[Rung]:
    """Every rung of the ladder, lowest first, run or not."""
    return [rung(evals, curves, episodes, name, runs) for name in RUNGS]


def training_costs(curves: pd.DataFrame, runs: pd.DataFrame | None = None) -> pd.DataFrame:
    """Per training (`train_key`): the hours it trained (`analysis.costs.hours_trained`: a training stopped and
    resumed in another session counts only its training time) and how many times it was resumed (its run's
    `resumes` tag)."""
    columns = ["train_key", "hours", "stops"]
    hours = hours_trained(curves)
    if hours.empty:
        return pd.DataFrame(columns=columns)
    costs = pd.DataFrame({"train_key": hours.index, "hours": hours.to_numpy()})
    stops = pd.Series(dtype=float)
    if runs is not None and {"resumes", "train_key", "stage"} <= set(runs.columns):
        trained = runs[runs["stage"] == "train"]
        stops = pd.to_numeric(trained.set_index("train_key")["resumes"], errors="coerce").groupby(level=0).max()
    costs["stops"] = costs["train_key"].map(stops).fillna(0).astype(int)
    return costs[columns]


def method_rows(r: Rung) -> pd.DataFrame:
    """One row per method of the rung and the human-driven host: seeds, the scenario-3 return and collisions
    per episode (mean over seeds, 95 % t interval over seeds) and the seeds beating the human-driven host
    (`paired_seeds` tested beside it, `beating` of them, `beating_text` as the seed-by-seed table words it)."""
    table = headline(r.evals, SCENARIOS) if not r.evals.empty else pd.DataFrame(columns=["model"])
    beating = seeds_beating(r.evals, REFERENCE, SCENARIOS, episodes=r.episodes)
    counts = beating.set_index("model")
    words = beating_grid(beating, SCENARIOS)[HEADLINE_SCENARIO] if not beating.empty else pd.Series(dtype=str)
    costs = training_costs(r.curves, r.runs)
    out = []
    for model in (*LEARNED, REFERENCE):
        row: dict[str, object] = {"rung": r.name, "model": model}
        found = table[table["model"] == model]
        for metric in HEADLINE_METRICS:
            for part in ("point", "low", "high", "n"):
                value = found.iloc[0][f"{metric}/scenario/{part}"] if not found.empty else float("nan")
                row[f"{metric}/{part}"] = value
        n = row[f"{HEADLINE_METRICS[0]}/n"]
        row["seeds"] = 0 if pd.isna(n) else int(n)
        for metric in DRIVING:
            row[metric] = float(per_scenario(r.evals, model, metric, SCENARIOS).get(HEADLINE_SCENARIO,
                                                                                   pd.Series(dtype=float)).mean())
        row["paired_seeds"] = int(counts.loc[model, "seeds"]) if model in counts.index else 0
        row["beating"] = int(counts.loc[model, "beating"]) if model in counts.index else 0
        row["beating_text"] = _beating_text(model, row, words)
        keys = set(r.evals.loc[r.evals["model"] == model, "train_key"].dropna())
        mine = costs[costs["train_key"].isin(keys)]
        row["trainings"] = len(mine)
        row["training_hours"] = float(mine["hours"].mean()) if len(mine) else float("nan")
        row["stops"] = int(mine["stops"].sum())
        out.append(row)
    return pd.DataFrame(out)


def estimate(point: float, low: float, high: float, n: int, metric: str) -> str:
    """'mean [low, high]' from `COVERAGE_SEEDS` seeds, the count at which the t interval's coverage is measured;
    below it the mean alone (the tables say how many seeds), as a t interval on fewer seeds claims a coverage no
    one has measured; 'n/a' with none."""
    if n >= COVERAGE_SEEDS:
        return fmt_estimate(point, low, high, n, metric)
    return fmt(point, metric) if n else "n/a"


def _cell(row: pd.Series, metric: str, absent: str = NOT_RUN) -> str:
    if not row["seeds"]:
        return absent
    return estimate(row[f"{metric}/point"], row[f"{metric}/low"], row[f"{metric}/high"], int(row["seeds"]), metric)


def _beating_text(model: str, row: dict[str, object], words: pd.Series) -> str:
    if model == REFERENCE:
        return "the reference" if row["seeds"] else "no runs: nothing to pair with"
    if not row["seeds"]:
        return NOT_RUN
    if not row["paired_seeds"]:
        return "no human-driven run on these seeds"
    return str(words[model])


def _table(r: Rung, going: set[tuple[str, str]] | frozenset[tuple[str, str]] = frozenset()) -> list[list[str]]:
    """The rung's table, a row per method; a method with no seed tested reads "under way" in its cells where
    `going` (`under_way`) holds it on this rung, else "not run"."""
    head = ["Method", "Seeds", f"Return, scenario {HEADLINE_SCENARIO}",
            f"{METRIC_LABELS['collisions']}, scenario {HEADLINE_SCENARIO}",
            f"Speed (km/h), lane changes, scenario {HEADLINE_SCENARIO}",
            f"Seeds beating the human-driven host, scenario {HEADLINE_SCENARIO}", "CPU-hours per training (stops)"]
    rows = [head]
    for _, row in method_rows(r).iterrows():
        name = model_label(row["model"], short=True) + (" (every rung)" if row["model"] == REFERENCE else "")
        absent = absence(r.name, going, row["model"])
        driving = (f"{fmt(row['avg_speed_kmh'], 'avg_speed_kmh')}, {fmt(row['lane_changes'], 'lane_changes')}"
                   if row["seeds"] else absent)
        beating = absent if row["beating_text"] == NOT_RUN else row["beating_text"]
        rows.append([name, str(row["seeds"]), _cell(row, "episode_return", absent),
                     _cell(row, "collisions", absent), driving, beating, _hours(row)])
    return rows


def against_base(ladder: list[Rung]) -> pd.DataFrame:
    """Per higher rung and learned method run on both it and the lowest rung: the rung's scenario-3 value minus
    the lowest rung's, for each of `SHIFT_METRICS`, paired by seed over the seeds both tested (a seed draws the
    same test traffic at every rung, so the pair differs in the preset alone). Columns: rung, model, metric,
    point, low, high (the 95 % t interval of the per-seed differences) and n (the seeds paired)."""
    columns = ["rung", "model", "metric", "point", "low", "high", "n"]
    base = next((r for r in ladder if r.name == BASE), None)
    out = []
    for r in ladder:
        if base is None or r.name == BASE or not r.ran:
            continue
        for model in LEARNED:
            for metric in SHIFT_METRICS:
                mine = per_scenario(r.evals, model, metric, SCENARIOS).get(HEADLINE_SCENARIO)
                theirs = per_scenario(base.evals, model, metric, SCENARIOS).get(HEADLINE_SCENARIO)
                if mine is None or theirs is None:
                    continue
                seeds = mine.index.intersection(theirs.index)
                if seeds.empty:
                    continue
                est = difference_ci({HEADLINE_SCENARIO: mine[seeds]}, {HEADLINE_SCENARIO: theirs[seeds]})
                out.append({"rung": r.name, "model": model, "metric": metric, "point": est.point, "low": est.low,
                            "high": est.high, "n": est.n})
    return pd.DataFrame(out, columns=columns)


def _shift_table(shifts: pd.DataFrame) -> list[list[str]]:
    head = ["Rung, method", "Seeds paired", *[f"{METRIC_LABELS[m]}" for m in SHIFT_METRICS]]
    rows = [head]
    for (name, model), group in shifts.groupby(["rung", "model"], sort=False):
        cells = group.set_index("metric")
        n = int(cells["n"].max())
        rows.append([f"{name}, {model_label(str(model), short=True)}", str(n),
                     *[estimate(cells.loc[m, "point"], cells.loc[m, "low"], cells.loc[m, "high"],
                                int(cells.loc[m, "n"]), m) if m in cells.index else "n/a"
                       for m in SHIFT_METRICS]])
    return rows


def _hours(row: pd.Series) -> str:
    if row["model"] == REFERENCE:
        return "does not train"
    if not row["trainings"]:
        return "-"
    return f"{row['training_hours']:.2f} ({row['stops']})"


TESTED, STOPPED, MISSING = "tested", "stopped", "missing"


def expected_seeds(evals: pd.DataFrame) -> list[object]:
    """The seeds every rung is to hold: those the human-driven host was tested on (it stands beside every
    rung), else those of any learned method at any rung."""
    for rows in (evals[evals["model"] == REFERENCE], evals[evals["model"].isin(LEARNED)]):
        if not rows.empty:
            return sorted(set(rows["seed"].dropna()), key=str)
    return []


def trainings(r: Rung, stopped: pd.DataFrame, seeds: list[object]) -> pd.DataFrame:
    """One row per learned method and expected seed of rung `r`: its state (tested: an evaluation run of the
    rung tested it; stopped: a signal stopped its training before the last step; missing: neither), the env
    steps reached of the total where stopped, and the hours it trained (tested: its whole training)."""
    costs = training_costs(r.curves, r.runs).set_index("train_key")
    mine = stopped[stopped["experiment"] == r.name] if not stopped.empty else stopped
    out = []
    for model in LEARNED:
        tested = r.evals[r.evals["model"] == model]
        for seed in seeds:
            row: dict[str, object] = {"rung": r.name, "model": model, "seed": seed, "state": MISSING,
                                      "step": float("nan"), "total_steps": float("nan"),
                                      "steps_per_s": float("nan"), "hours": float("nan"), "stops": 0}
            keys = set(tested.loc[tested["seed"] == seed, "train_key"].dropna())
            under_way = mine[(mine["model"] == model) & (mine["seed"] == seed)] if not mine.empty else mine
            if keys:
                row["state"] = TESTED
                known = costs[costs.index.isin(keys)]
                if len(known):
                    row["hours"] = float(known["hours"].sum())
                    row["stops"] = int(known["stops"].sum())
            elif len(under_way):
                first = under_way.iloc[0]
                row.update(state=STOPPED, step=float(first["step"]), total_steps=float(first["total_steps"]),
                           steps_per_s=float(first["steps_per_s"]), hours=float(first["hours"]),
                           stops=int(first["stops"]))
            out.append(row)
    return pd.DataFrame(out, columns=["rung", "model", "seed", "state", "step", "total_steps", "steps_per_s",
                                      "hours", "stops"])


def _rest(row: pd.Series) -> float:
    """Hours a stopped training still needs: its remaining steps at the slowest rate it logged (NaN if unknown)."""
    if row["step"] > 0 and pd.notna(row["total_steps"]) and pd.notna(row["steps_per_s"]) and row["steps_per_s"] > 0:
        return max(float(row["total_steps"] - row["step"]), 0.0) / float(row["steps_per_s"]) / 3600
    return float("nan")


def hours_per_training(states: pd.DataFrame) -> float:
    """What one training of the rung takes, as measured here: the mean of its tested trainings' hours, else of
    its stopped ones' hours so far plus their remaining steps at the slowest rate each logged; NaN when neither
    was measured."""
    done = states[(states["state"] == TESTED) & states["hours"].notna()]
    if len(done):
        return float(done["hours"].mean())
    going = states[states["state"] == STOPPED]
    whole = (going["hours"] + going.apply(_rest, axis=1)).dropna() if len(going) else pd.Series(dtype=float)
    return float(whole.mean()) if len(whole) else float("nan")


def method_hours(states: pd.DataFrame) -> dict[str, float]:
    """Per method of `states`: what one of its trainings takes on the rung, by `hours_per_training` over its own
    trainings, else over the whole rung's (methods differ: Coordinate's network is not the proposed host's)."""
    rung = hours_per_training(states)
    out = {}
    for model, group in states.groupby("model", sort=False):
        own = hours_per_training(group)
        out[str(model)] = rung if pd.isna(own) else own
    return out


def hours_left(states: pd.DataFrame, per_method: dict[str, float] | None = None) -> float:
    """Hours of training the rung still needs: each stopped training's remaining steps at the slowest rate it
    logged (a whole training where that is unknown), and a whole training of its method (`per_method`, by default
    `method_hours(states)`) per missing one; NaN when nothing on the rung was measured yet."""
    per_method = method_hours(states) if per_method is None else per_method
    rest = 0.0
    for _, row in states[states["state"] != TESTED].iterrows():
        per_training = per_method[str(row["model"])]
        own = _rest(row) if row["state"] == STOPPED else float("nan")
        rest += per_training if pd.isna(own) else own
    return rest


def _seed_list(seeds: list[object]) -> str:
    words = [str(s) for s in seeds]
    return f"seed {words[0]}" if len(words) == 1 else f"seeds {', '.join(words[:-1])} and {words[-1]}"


def _steps(value: float) -> str:
    return f"{value / 1e6:g}M" if value >= 1e6 else f"{value / 1e3:.0f}k"


def progress_text(states: pd.DataFrame) -> str:
    """The rung's trainings in words: per method, the seeds tested, each stopped one's steps and hours, the
    seeds missing; then the hours left."""
    if states.empty:
        return "No seeds to train: the store holds no human-driven run to pair with."
    parts = []
    for model, group in states.groupby("model", sort=False):
        words = []
        tested = list(group.loc[group["state"] == TESTED, "seed"])
        if tested:
            words.append(f"{_seed_list(tested)} tested")
        for _, row in group[group["state"] == STOPPED].iterrows():
            total = f" of {_steps(row['total_steps'])}" if pd.notna(row["total_steps"]) else ""
            times = "once" if row["stops"] == 1 else f"{row['stops']} times"
            resumed = f", resumed {times}" if row["stops"] else ""
            words.append(f"seed {row['seed']} stopped at {_steps(row['step'])}{total} steps after "
                         f"{row['hours']:.2f} CPU-hours of training{resumed}")
        missing = list(group.loc[group["state"] == MISSING, "seed"])
        if missing:
            words.append(f"{_seed_list(missing)} missing")
        parts.append(f"{model_label(str(model), short=True)}: {'; '.join(words)}")
    text = "Trainings: " + ". ".join(parts) + "."
    if (states["state"] == TESTED).all():
        return text
    if pd.isna(hours_per_training(states)):
        return text + " Left: every training; none has logged its rate yet, so the hours are not measured here."
    per_method = method_hours(states)
    waiting = states.loc[states["state"] != TESTED, "model"].drop_duplicates()
    each = listed([f"{model_label(str(m), short=True)} {per_method[str(m)]:.1f}" for m in waiting])
    left = hours_left(states, per_method)
    return (text + f" Left: {_about_hours(left)} of training, at what one training takes as "
            f"measured on this rung: {each} CPU-hours (the method's tested trainings, else a stopped one's hours "
            "so far and the rest of its steps at the slowest rate it logged, else the rung's), and the tests.")


def _about_hours(hours: float) -> str:
    """'about 3 CPU-hours', 'about 1 CPU-hour', 'under half a CPU-hour'."""
    if hours < 0.5:
        return "under half a CPU-hour"
    whole = round(hours)
    return f"about {whole} CPU-hour{'' if whole == 1 else 's'}"


def _method_words(row: pd.Series, expected: int) -> str:
    """'Proposed 80.3 return, 0.640 collisions (2 of 5 seeds, no CI; 0 beat the human-driven host)' for a method
    with tests on the rung, per episode (the rung's line says so once): an interval from `COVERAGE_SEEDS` seeds
    only (`estimate`). Page 1 has room for few words: the seed count says "of `expected`" only while short of
    it, and the count beating the human-driven host says "of" only where fewer seeds were paired than tested."""
    n = int(row["seeds"])
    # The seeds are said once, after both numbers.
    return_, collisions = (estimate(row[f"{m}/point"], row[f"{m}/low"], row[f"{m}/high"], n, m)
                           for m in HEADLINE_METRICS)
    seeds = f"{n} of {expected} seeds" if expected and n < expected else f"{n} seeds"
    paired = int(row["paired_seeds"])
    beating = f"{row['beating']} of {paired}" if paired != n else f"{row['beating']}"
    return (f"{model_label(str(row['model']), short=True)} {return_} return, {collisions} collisions "
            f"({seeds}{', no CI' if n < COVERAGE_SEEDS else ''}; {beating} beat the human-driven host)")


def under_way(trainings: pd.DataFrame) -> set[tuple[str, str]]:
    """The (rung, model) pairs with a training stopped part-way, from `section`'s trainings table."""
    going = trainings[trainings["state"] == STOPPED]
    return set(zip(going["rung"], going["model"], strict=True))


def page_one_lines(numbers: pd.DataFrame, shown: set[str], expected: int,
                   going: set[tuple[str, str]] | frozenset[tuple[str, str]] = frozenset()) -> list[str]:
    """What the rungs that the report's other pages do not show (`shown`: their presets) found so far, one line
    per rung, with `expected` seeds per method, for the report's first page beside the scale of its runs; none
    while no such rung has run. A method with no seed tested reads "under way" where `going` (`under_way`) holds
    its rung, else "not run"."""
    above = numbers[~numbers["rung"].isin(shown) & numbers["model"].isin(LEARNED)]
    if not above["seeds"].gt(0).any():
        return []
    lines = []
    for name in [r for r in RUNGS if r in set(above["rung"])]:
        rows = above[above["rung"] == name]
        label = RUNGS[name][0].upper() + RUNGS[name][1:]
        if not rows["seeds"].any():
            started = [model_label(m, short=True) for m in rows["model"] if (name, m) in going]
            lines.append(f"{label}: {listed(started)} {UNDER_WAY}, no seed tested yet (scale ladder)." if started
                         else f"{label}: {NOT_RUN} yet (scale ladder).")
            continue
        tested = [_method_words(row, expected) for _, row in rows.iterrows() if row["seeds"]]
        untested = [str(m) for m in rows.loc[rows["seeds"] == 0, "model"]]
        started = [model_label(m, short=True) for m in untested if (name, m) in going]
        missing = [model_label(m, short=True) for m in untested if (name, m) not in going]
        lines.append(f"{label}, scenario {HEADLINE_SCENARIO}, per episode (scale ladder): " + "; ".join(tested)
                     + (f"; {listed(started)} {UNDER_WAY}, no seed tested yet" if started else "")
                     + (f"; {listed(missing)} {NOT_RUN}" if missing else "") + ".")
    return lines


def claim_verdicts(ladder: list[Rung]) -> pd.DataFrame:
    """Claim x rung: each claim's verdict on the rung's runs alone, or 'not run'."""
    columns = {r.name: ({c.number: c.verdict for c in r.claims()} if r.ran else dict.fromkeys(CLAIMS, NOT_RUN))
               for r in ladder}
    return pd.DataFrame(columns, index=pd.Index(list(CLAIMS), name="claim"))


def section(evals: pd.DataFrame, curves: pd.DataFrame, episodes: pd.DataFrame,
            runs: pd.DataFrame | None = None, stopped: pd.DataFrame | None = None, out_dir: Path | None = None,
            ) -> tuple[Section, pd.DataFrame, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The ladder as a report section, with its numbers (rung x method), verdicts (claim x rung), trainings
    (rung x method x seed: tested, stopped or missing) and shifts (`against_base`: each higher rung minus the
    lowest, paired by seed) as tables for CSV files; with `out_dir`, its figure (`analysis.ladder_figure`) is
    saved there and leads the section."""
    ladder = rungs(evals, curves, episodes, runs)
    stopped = no_stopped() if stopped is None else stopped
    seeds = expected_seeds(evals)
    states = {r.name: trainings(r, stopped, seeds) for r in ladder}
    out = Section(TITLE)
    out.para("The same comparison at each rung of the paper's scale within this CPU's reach, lowest first. A "
             "rung is an experiment preset: its learned hosts were trained and tested with it. The human-driven "
             "host does not train, so its runs (the same seeds in the same scenarios, hence the same test traffic) "
             "stand beside every rung. Only the paper's three methods are on the ladder: the variants (the "
             "enriched HGM, the guarded hosts) are left out. Return and collisions: per test episode in scenario "
             f"{HEADLINE_SCENARIO} (the training traffic's mix), mean over seeds [95 % t interval over seeds, shown "
             f"from {COVERAGE_SEEDS} seeds, the count at which its coverage is measured: below it, the mean alone]; "
             "speed and lane changes: the mean test speed and lane changes per episode there, mean over seeds. A "
             f"seed beats the human-driven host when its return is higher on the same seed and scenario with under "
             f"{SAFE_COLLISIONS:g} collisions per episode. CPU-hours per training: the mean over the method's "
             "trainings of the CPU time spent training (env steps over the rate logged per second of the training "
             "process's CPU time, summed over the logged intervals, so that neither the other load on a shared "
             "machine nor a stop between sessions counts; a training that logged only its wall-clock rate counts "
             "its wall time; the CPU time counts every thread of the process, so a CPU-hour is a core-hour whether "
             "the training ran on one core or, alone, on two); stops: how many times "
             "its trainings were stopped and resumed, each without its replay memory.")
    numbers = pd.concat([method_rows(r).assign(label=r.label, ran=r.ran) for r in ladder], ignore_index=True)
    going = under_way(pd.concat(states.values(), ignore_index=True))
    paths = (ladder_figure.figure(ladder, numbers, REFERENCE, out_dir / FIGURE, going)
             if out_dir is not None else None)
    if paths is not None:
        out.figure(paths["png"], f"Each rung's scenario-{HEADLINE_SCENARIO} return and collisions per episode, per "
                                 "method: one dot per seed, the mean over seeds (diamond) and its 95 % t interval "
                                 f"(from {COVERAGE_SEEDS} seeds, as in the tables); the human-driven "
                                 "host's mean and interval as the dashed line and grey band. n: the seeds tested.")
    for i, r in enumerate(ladder, start=1):
        if not r.ran:
            state = absence(r.name, going)
            out.para(f"Rung {i}, {r.name}: {r.label}: {state}. {progress_text(states[r.name])}")
            continue
        out.para(f"Rung {i}, {r.name}: {r.label}. {progress_text(states[r.name])}")
        out.table(_table(r, going), widths=[1.15, 0.55, 1.4, 1.4, 0.95, 1.25, 0.9])
    shifts = against_base(ladder)
    if not shifts.empty:
        out.para(f"What each higher rung changes against the {BASE} rung, method by method: the rung's scenario-"
                 f"{HEADLINE_SCENARIO} value minus the {BASE} rung's, paired by seed over the seeds both tested (a "
                 "seed draws the same test traffic at every rung, so a pair differs in the preset alone), mean "
                 "[95 % t interval of the per-seed differences, shown from "
                 f"{COVERAGE_SEEDS} seeds paired, the count at which its coverage is measured]. An interval that "
                 "holds 0 says the rung has not shown a change on these seeds; with fewer seeds paired, the mean "
                 "alone is a guide, not a verdict.")
        out.table(_shift_table(shifts), widths=[1.55, 0.55, 1.4, 1.4, 1.15, 1.15])
    verdicts = claim_verdicts(ladder)
    out.para("Each claim's verdict on each rung's runs alone, by the rule of the claims section (training "
             "claims read the training curves of the networks the rung tested). A claim made of several "
             "comparisons reads not supported as soon as one of them is, even while another method's runs are "
             "still missing (their comparisons could not make it hold); on a rung short of its seeds, more seeds "
             "can still move any verdict.")
    out.table([["Claim", *[f"{r.name}" for r in ladder]],
               *[[f"{n}. {CLAIMS[n]}", *[str(verdicts.loc[n, r.name]) for r in ladder]] for n in verdicts.index]],
              widths=[3.4, *[1.0] * len(ladder)])
    return out, numbers, verdicts.reset_index(), pd.concat(list(states.values()), ignore_index=True), shifts


def main_view(data: StoreData) -> StoreData:
    """`data` cut to each model's main experiment (the report's pages other than the ladder), with a note per
    model whose other presets' runs only the ladder page reads."""
    evals = data.evals
    main = main_experiments(evals)
    if all(len(set(g)) <= 1 for _, g in evals.groupby("model")["experiment"]):
        return data
    kept = at_main_experiments(evals)
    notes = []
    for model, group in evals[~evals.index.isin(kept.index)].groupby("model"):
        others = ", ".join(f"{e} ({n} evaluation runs)" for e, n in group["experiment"].value_counts().sort_index()
                           .items())
        notes.append(f"{model_label(str(model), short=True)}: its runs of {others} are read by the scale-ladder "
                     f"page only; the other pages read its {main[str(model)]} runs.")
    keys = set(kept["train_key"].dropna())
    tested = set(evals["model"])

    def trained_here(frame: pd.DataFrame) -> pd.Series:
        # A training belongs to the main pages when one of their evaluation runs tested it.
        return frame["train_key"].isin(keys) | ~frame["model"].isin(tested)

    runs = data.runs
    is_eval = runs["stage"] == "eval"
    runs = runs[(is_eval & runs["run_id"].isin(set(kept["run_id"]))) | (~is_eval & trained_here(runs))]
    curves = data.curves[trained_here(data.curves)] if not data.curves.empty else data.curves
    episodes = data.episodes[data.episodes["run_id"].isin(set(kept["run_id"]))] if "run_id" in data.episodes \
        else data.episodes
    return dataclasses.replace(data, evals=kept.reset_index(drop=True), runs=runs.reset_index(drop=True),
                               curves=curves.reset_index(drop=True), episodes=episodes.reset_index(drop=True),
                               dropped=[*data.dropped, *notes])
