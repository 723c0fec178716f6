"""The safest network beside the preset's own: each training tested again from its safest kept validation
pass (`eval.checkpoint=safest`; results named `<host>_safest`), compared seed by seed with the same
training's test of the network its preset tests (best.pt at the quick presets). A refused choice opens no test
run; the training run's tags (SAFEST_TAGS) say it was refused, so a host whose every training was refused is
named too. Shown only when the runs hold such tests or refusals."""

from __future__ import annotations

import pandas as pd

from analysis.labels import SAFEST, fmt, model_label, ordered_models
from analysis.sections import Section
from analysis.stats import NO_DATA, Estimate, mean_ci, per_seed
from analysis.tables import HEADLINE_SCENARIO, in_range, per_scenario
from hgm_repro.contracts.names import SAFEST_REFUSED, SAFEST_TAGS

TITLE = "The safest network beside best.pt"
BAR_PARAM = "params.eval.safest_max_collisions"


def _series(evals: pd.DataFrame, model: str, metric: str, scenario: str | None) -> pd.Series:
    """Per-seed values of `metric`: in `scenario`, or each seed's mean over the scenarios it was tested in
    (None); seeds missing a scenario the model holds elsewhere are left out."""
    strata = per_scenario(evals, model, metric)
    if scenario is not None:
        return strata.get(scenario, pd.Series(dtype=float))
    return per_seed(strata) if strata else pd.Series(dtype=float)


def _cell(est: Estimate, metric: str, ranged: bool = True) -> str:
    if est.n == 0:
        return "-"
    if not est.has_ci:
        return f"{fmt(est.point, metric)} (1 seed)"
    est = in_range(est, metric) if ranged else est  # a difference has no such range
    return f"{fmt(est.point, metric)} [{fmt(est.low, metric)}, {fmt(est.high, metric)}]"


def paired(evals: pd.DataFrame, host: str, metric: str, scenario: str | None) -> Estimate:
    """safest minus the preset's network over the seeds both were tested on (the same test traffic)."""
    mine = _series(evals, f"{host}_safest", metric, scenario)
    theirs = _series(evals, host, metric, scenario)
    seeds = mine.index.intersection(theirs.index)
    if seeds.empty:
        return NO_DATA
    return mean_ci((mine[seeds] - theirs[seeds]).to_numpy())


def bars(runs: pd.DataFrame | None) -> list[str]:
    """The collision bars the safest tests were chosen under (normally one)."""
    if runs is None or BAR_PARAM not in runs:
        return []
    tested = runs[runs["model"].isin(list(SAFEST)) & runs["stage"].eq("eval")] if "stage" in runs else runs.iloc[:0]
    return sorted({str(v) for v in tested[BAR_PARAM].dropna()})


REFUSAL_COLUMNS = ["host", "seed", "train_key", "lowest_collisions", "bar"]


def refusals(evals: pd.DataFrame, runs: pd.DataFrame | None) -> pd.DataFrame:
    """The trainings whose safest choice was refused (REFUSAL_COLUMNS): training runs of a host that has a
    safest form, among the trainings `evals` tested (so of the same presets), with the host, the seed, the
    fewest collisions per episode any kept pass had, and the bar."""
    choice, bar_tag, lowest_tag = SAFEST_TAGS
    if runs is None or runs.empty or choice not in runs or evals.empty or "train_key" not in evals:
        return pd.DataFrame(columns=REFUSAL_COLUMNS)
    refused = runs[runs["stage"].eq("train") & runs[choice].eq(SAFEST_REFUSED)
                   & runs["model"].isin(set(SAFEST.values())) & runs["train_key"].isin(set(evals["train_key"]))]
    refused = refused.drop_duplicates("train_key")
    return pd.DataFrame({
        "host": refused["model"], "seed": refused["seed"], "train_key": refused["train_key"],
        "lowest_collisions": pd.to_numeric(refused[lowest_tag], errors="coerce"),
        "bar": pd.to_numeric(refused[bar_tag], errors="coerce"),
    }, columns=REFUSAL_COLUMNS).reset_index(drop=True)


def _hosts(evals: pd.DataFrame, refused: pd.DataFrame) -> list[str]:
    """The hosts with safest tests or refusals, in the report's order."""
    tested = {SAFEST[m] for m in evals["model"].unique() if m in SAFEST}
    return list(ordered_models(tested | set(refused["host"])))


def table(evals: pd.DataFrame, scenario: str = HEADLINE_SCENARIO) -> list[list[str]]:
    """Per host with safest tests: its preset's network and its safest network, scenario `scenario` and the
    mean over the scenarios, return and collisions with their intervals over seeds."""
    head = ["Host", "Tested network", f"Return, scenario {scenario}", f"Collisions, scenario {scenario}",
            "Return, all scenarios", "Collisions, all scenarios", "Seeds"]
    rows = [head]
    for name in ordered_models(m for m in evals["model"].unique() if m in SAFEST):
        host = SAFEST[name]
        for model, network in ((host, "its preset's (best.pt)"), (name, "safest")):
            cells = [_cell(mean_ci(_series(evals, model, metric, where)), metric)
                     for where in (scenario, None) for metric in ("episode_return", "collisions")]
            seeds = _series(evals, model, "episode_return", scenario).index
            rows.append([model_label(host, short=True), network, *cells, str(len(seeds))])
    return rows


def _seeds(seeds: list[object]) -> str:
    return f"seed{'s' if len(seeds) != 1 else ''} {', '.join(map(str, seeds))}"


def _refused_words(rows: pd.DataFrame) -> str:
    """'seeds 1, 2 were refused: ...' for one host's refused trainings."""
    seeds = sorted(rows["seed"], key=str)
    low, high = rows["lowest_collisions"].min(), rows["lowest_collisions"].max()
    crashed = fmt(low, "collisions") if low == high else f"{fmt(low, 'collisions')}-{fmt(high, 'collisions')}"
    bar = " or ".join(f"{b:g}" for b in sorted(rows["bar"].dropna().unique()))  # as it was given
    return (f"{_seeds(seeds)} {'were' if len(seeds) != 1 else 'was'} refused: no kept pass stayed under {bar} "
            f"collisions per episode (the safest crashed {crashed} times per episode on the validation drives)")


def sentences(evals: pd.DataFrame, refused: pd.DataFrame | None = None) -> list[str]:
    """Per host: what the safest network changes, seed by seed, and which trainings have no safest test:
    refused (no kept pass under the bar), or not run."""
    refused = pd.DataFrame(columns=REFUSAL_COLUMNS) if refused is None else refused
    out = []
    for host in _hosts(evals, refused):
        label = model_label(host, short=True)
        mine = refused[refused["host"] == host]
        tested = set(evals.loc[evals["model"] == f"{host}_safest", "seed"])
        if not tested:
            out.append(f"{label}: no safest test; {_refused_words(mine)}.")
            continue
        ret, crashes = paired(evals, host, "episode_return", None), paired(evals, host, "collisions", None)
        text = (f"{label}: the safest network minus best.pt, over the {ret.n} seed{'s' if ret.n != 1 else ''} tested "
                f"both ways and every scenario, changes the return by {_cell(ret, 'episode_return', ranged=False)} "
                f"per episode and the collisions by {_cell(crashes, 'collisions', ranged=False)}")
        if not mine.empty:
            text += f". Of its other trainings, {_refused_words(mine)}"
        trained = set(evals.loc[evals["model"] == host, "seed"])
        missing = sorted(trained - tested - set(mine["seed"]), key=str)
        if missing:
            text += f". {_seeds(missing).capitalize()} {'have' if len(missing) != 1 else 'has'} no safest test yet"
        out.append(text + ".")
    return out


def section(evals: pd.DataFrame, runs: pd.DataFrame | None = None) -> Section | None:
    """The report's section on the safest network, or None when no run tested one and none was refused."""
    refused = refusals(evals, runs)
    if evals.empty or (not evals["model"].isin(list(SAFEST)).any() and refused.empty):
        return None
    out = Section(TITLE)
    bar = bars(runs)
    under = f"under {' or '.join(bar)} collisions per episode" if bar else "under the bar"
    out.para("best.pt is the validation pass with the highest return, whatever it cost in crashes. The safest "
             "network is chosen from the same training's kept validation passes: each pass drives again on at least "
             f"256 validation episodes (the training traffic, seeds no test uses), and the best return {under} "
             "wins. Both are tested on the same test traffic, so the two rows of a host differ only in the network "
             "chosen. A choice of network, not a method: no claim reads it.")
    if evals["model"].isin(list(SAFEST)).any():
        out.table(table(evals), widths=[1.2, 1.1, 1.3, 1.1, 1.3, 1.1, 0.6])
    for sentence in sentences(evals, refused):
        out.para(sentence)
    return out
