"""On equal terms: the paper's claims judged again with each learned method replaced by its guarded
form (trained and tested under the human-driven host's safety layer, conf/model/*_guarded.yaml),
against the same human-driven host in the same test traffic; and the mark a host under that layer can
aim at, IDM + MOBIL's return under the same layer. Shown only when the runs hold guarded models."""

from __future__ import annotations

import pandas as pd

from analysis.claims import ClaimResult, evaluate_claims
from analysis.labels import GUARDED, LAYER_AT_TEST, LEARNED, fmt, model_label
from analysis.sections import Section
from analysis.stats import mean_ci
from analysis.tables import HEADLINE_SCENARIO, per_scenario, seed_margins

# A guarded host drives under the layer that keeps the human-driven host crash-free, so a seed on which it
# beats that host counts only when it is nearly as safe: under this many collisions per episode.
GUARDED_SAFE_COLLISIONS = 0.05

TITLE = "On equal terms: the learned hosts under the safety layer"


def has_guarded(evals: pd.DataFrame) -> bool:
    return bool(evals["model"].isin(list(GUARDED)).any()) if not evals.empty else False


def substituted(frame: pd.DataFrame) -> pd.DataFrame:
    """`frame` (evals or curves) with each paper method's rows replaced by its guarded form's, under the
    method's name, so that the claims' machinery reads the guarded hosts where it reads the methods."""
    kept = frame[~frame["model"].isin(LEARNED)]
    return kept.assign(model=kept["model"].replace(GUARDED)).reset_index(drop=True)


def guarded_claims(evals: pd.DataFrame, curves: pd.DataFrame) -> list[ClaimResult]:
    return evaluate_claims(substituted(evals), substituted(curves))


def _mean(evals: pd.DataFrame, model: str, metric: str, scenario: str) -> tuple[float, int]:
    est = mean_ci(per_scenario(evals, model, metric, [scenario]).get(scenario, []))
    return est.point, est.n


def mark_sentence(evals: pd.DataFrame, scenario: str = HEADLINE_SCENARIO) -> str:
    """The guarded proposed host's return in `scenario` against IDM + MOBIL's and the human-driven host's,
    each under the same layer, in plain words."""
    mine, n = _mean(evals, "proposed_guarded", "episode_return", scenario)
    if n == 0:
        return f"The guarded proposed host has no test in scenario {scenario}."
    crashes, _ = _mean(evals, "proposed_guarded", "collisions", scenario)
    text = (f"In scenario {scenario} the guarded proposed host earns {fmt(mine, 'episode_return')} per episode "
            f"(mean of {n} seed{'s' if n != 1 else ''}, {fmt(crashes, 'collisions')} collisions per episode)")
    mark, n_mark = _mean(evals, "idm_mobil", "episode_return", scenario)
    human, n_human = _mean(evals, "human", "episode_return", scenario)
    if n_mark == 0:
        return text + "; IDM + MOBIL, the mark under the same layer, has no test in these runs."
    text += (f", against {fmt(mark, 'episode_return')} for IDM + MOBIL under the same layer: the mark a decision "
             f"maker with this layer can aim at")
    if n_human and mark != human:
        text += (f". The human-driven host earns {fmt(human, 'episode_return')}, so the guarded proposed host covers "
                 f"{(mine - human) / (mark - human):.0%} of the way from it to IDM + MOBIL")
    return text + "."


def seeds_sentence(evals: pd.DataFrame, scenario: str = HEADLINE_SCENARIO) -> str | None:
    """On how many seeds the guarded proposed host beats the human-driven host of the same seed in `scenario`
    (more return, under `GUARDED_SAFE_COLLISIONS` collisions per episode), or None without both hosts' tests."""
    margins = seed_margins(evals, max_collisions=GUARDED_SAFE_COLLISIONS)
    mine = margins[(margins["model"] == "proposed_guarded") & (margins["scenario"] == scenario)]
    if mine.empty:
        return None
    return (f"Seed by seed in scenario {scenario}, the guarded proposed host earns more than the human-driven host "
            f"of the same seed, with under {GUARDED_SAFE_COLLISIONS:g} collisions per episode, on "
            f"{int(mine['beating'].sum())} of {len(mine)} seeds.")


def _said(evals: pd.DataFrame, model: str, scenario: str) -> tuple[str, int]:
    """'R per episode with C collisions and L lane changes (n seeds)' of `model` in `scenario`, and n."""
    (ret, n), (crashes, _), (changes, _) = (_mean(evals, model, k, scenario)
                                            for k in ("episode_return", "collisions", "lane_changes"))
    return (f"{fmt(ret, 'episode_return')} per episode with {fmt(crashes, 'collisions')} collisions and "
            f"{fmt(changes, 'lane_changes')} lane changes ({n} seeds)"), n


def probe_sentences(evals: pd.DataFrame, scenario: str = HEADLINE_SCENARIO) -> list[str]:
    """For each network tested under the layer it trained without: its scenario's return, collisions and lane
    changes, beside the same trainings tested as they trained."""
    out = []
    for probe, method in LAYER_AT_TEST.items():
        under, n = _said(evals, probe, scenario)
        if n == 0:
            continue
        text = f"{model_label(probe)}: in scenario {scenario} it earns {under}"
        as_trained, n_trained = _said(evals, method, scenario)
        if n_trained:
            text += f", against {as_trained} as trained, without the layer"
        out.append(text + ". A probe of what the layer alone does, not a method: the network never drove under it.")
    return out


def section(evals: pd.DataFrame, curves: pd.DataFrame, paper_claims: list[ClaimResult]) -> Section | None:
    """The report's "On equal terms" section, or None when the runs hold no guarded model."""
    if not has_guarded(evals):
        return probe_section(evals)
    out = Section(TITLE)
    out.para("The human-driven host drives under the simulator's safety layer (gap acceptance for lane changes, a "
             "safe following speed, a cruise set-point its actions move); the paper's learned hosts drive without "
             "one. Here each learned method is replaced by its guarded form, trained and tested under the same layer "
             "(not the paper's methods), and the paper's claims are judged again with the same rules against the same "
             "human-driven host in the same test traffic. The layer is the same for every host: a learned host "
             "cannot see that it may change left only on even decisions and right only on odd ones, and the crash "
             "anatomy's refusal table measures what that costs it. In the evidence below, Proposed, Min and Coordinate "
             "name their guarded forms.")
    out.para(mark_sentence(evals))
    if (seeds := seeds_sentence(evals)) is not None:
        out.para(seeds)
    guarded = guarded_claims(evals, curves)
    paper = {c.number: c.verdict for c in paper_claims}
    out.table([["Claim", "Statement", "Paper's methods", "Guarded forms"],
               *[[str(c.number), c.statement, paper.get(c.number, "n/a"), c.verdict] for c in guarded]],
              widths=[0.5, 4.4, 1.0, 1.0])
    for claim in guarded:
        evidence = "; ".join(c.text() for c in claim.comparisons)
        out.para(f"Claim {claim.number} on the guarded forms, {claim.verdict}: {evidence}.")
    for sentence in probe_sentences(evals):
        out.para(sentence)
    return out


def probe_section(evals: pd.DataFrame) -> Section | None:
    """Without guarded trainings, the probe alone (networks tested under the layer they trained without)."""
    sentences = probe_sentences(evals)
    if not sentences:
        return None
    out = Section("The safety layer at test only")
    for sentence in sentences:
        out.para(sentence)
    return out
