"""The paper's seven claims, each judged from our runs with the numbers behind the verdict.

Every claim is broken into comparisons. Each comparison is an `Estimate` of a difference signed
so that a positive value is what the paper claims, with its 95 % Student-t interval over seeds
(`analysis.stats`). The rule for one comparison:

- supported:      at least MIN_SEEDS seeds per group and the interval lies above 0;
- not supported:  at least MIN_SEEDS seeds per group and the interval lies below 0;
- tie:            at least MIN_SEEDS seeds per group and the interval covers 0;
- inconclusive:   too few seeds for an interval, or data missing.

A claim made of several comparisons ("faster than both", "in every scenario") is supported only if
all of them are, not supported if any one is, inconclusive if any lacks data, and a tie otherwise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from analysis.curves import area_values, by_model, final_values, fluctuation_values
from analysis.labels import LEARNED, SCENARIOS, fmt, model_label
from analysis.scenarios import PAPER_CV_RATIO
from analysis.stats import Estimate, difference_ci, probability_of_improvement, slope_ci, slope_difference_ci
from analysis.tables import per_scenario

SUPPORTED = "supported"
NOT_SUPPORTED = "not supported"
TIE = "tie"
INCONCLUSIVE = "inconclusive"
VERDICTS = (SUPPORTED, NOT_SUPPORTED, TIE, INCONCLUSIVE)
# Two seeds give a valid t interval, but with one degree of freedom it is so wide that a verdict from it
# rests on which two networks happened to be trained: three seeds is the least a verdict is read from.
MIN_SEEDS = 3

CLAIMS = {
    1: "All three learned methods drive faster than the non-intelligent (human-driven) host.",
    2: "The proposed method learns faster and reaches a higher average speed than Min and Coordinate.",
    3: "The proposed method makes fewer lane changes than the others, in training and in test.",
    4: "Min's method fluctuates more in overtakes during training.",
    5: "In test, the proposed method beats both others in every scenario.",
    6: "The proposed method's test score rises with the CV ratio; Min's stays flat.",
    7: "Coordinate scores below proposed: the HGM is what helps.",
}


@dataclass
class Comparison:
    """One signed difference (positive = as the paper claims) and its verdict."""

    label: str
    estimate: Estimate
    verdict: str
    reason: str
    digits: int = 2

    def number(self) -> str:
        """'1.5 [1.1, 2.0]', the point with its interval (or why there is none)."""
        e = self.estimate
        if np.isnan(e.point):
            return "no data"
        ci = (f"[{fmt(e.low, digits=self.digits)}, {fmt(e.high, digits=self.digits)}]" if e.has_ci
              else "no interval")
        return f"{fmt(e.point, digits=self.digits)} {ci}"

    def text(self) -> str:
        e = self.estimate
        if np.isnan(e.point):
            return f"{self.label}: no data -> {self.verdict}"
        # Only an undecided comparison needs its reason; the others say it in the verdict word.
        why = f" ({self.reason})" if self.verdict in (INCONCLUSIVE, NOT_SUPPORTED) else ""
        return f"{self.label}: {self.number()}, n={e.n} -> {self.verdict}{why}"


@dataclass
class ClaimResult:
    number: int
    statement: str
    verdict: str
    rule: str
    comparisons: list[Comparison] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def judge(estimate: Estimate, min_seeds: int = MIN_SEEDS) -> tuple[str, str]:
    """Verdict of one comparison, with the reason in words."""
    if np.isnan(estimate.point):
        return INCONCLUSIVE, "missing data"
    if estimate.n < min_seeds:
        what = "no confidence interval" if estimate.n < 2 else f"fewer than {min_seeds} seeds"
        return INCONCLUSIVE, f"{estimate.n} seed{'s' if estimate.n != 1 else ''}: {what}"
    side = estimate.excludes_zero()
    if side > 0:
        return SUPPORTED, "interval above 0"
    if side < 0:
        return NOT_SUPPORTED, "the opposite holds"
    return TIE, "interval covers 0"


def combine(verdicts: list[str]) -> str:
    if not verdicts:
        return INCONCLUSIVE
    if NOT_SUPPORTED in verdicts:
        return NOT_SUPPORTED
    if all(v == SUPPORTED for v in verdicts):
        return SUPPORTED
    if INCONCLUSIVE in verdicts:
        return INCONCLUSIVE
    return TIE


def _compare(label: str, estimate: Estimate, min_seeds: int, digits: int = 2) -> Comparison:
    verdict, reason = judge(estimate, min_seeds)
    return Comparison(label, estimate, verdict, reason, digits)


def _claim(number: int, rule: str, comparisons: list[Comparison], notes: list[str] | None = None) -> ClaimResult:
    return ClaimResult(number, CLAIMS[number], combine([c.verdict for c in comparisons]), rule, comparisons,
                       notes or [])


def _test_scenarios(evals: pd.DataFrame) -> list[str]:
    # Test claims use the paper's five scenarios; a store evaluated only elsewhere falls back to
    # whatever scenarios it has, so that a partial sweep still gets numbers.
    present = [s for s in SCENARIOS if s in set(evals["scenario"])]
    return present or sorted(set(evals["scenario"]))


def _eval_diff(evals: pd.DataFrame, a: str, b: str, metric: str, scenarios: list[str]) -> Estimate:
    return difference_ci(per_scenario(evals, a, metric, scenarios), per_scenario(evals, b, metric, scenarios))


def _curve_diff(values: pd.DataFrame, a: str, b: str) -> Estimate:
    return difference_ci(by_model(values, a), by_model(values, b))


def claim1(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    sc = _test_scenarios(evals)
    comps = [_compare(f"{model_label(m, True)} - Human, test speed (km/h)",
                      _eval_diff(evals, m, "human", "avg_speed_kmh", sc), min_seeds, 1)
             for m in ("proposed", "min", "coordinate")]
    return _claim(1, "Mean test speed (km/h) of each learned method minus the human-driven host's, averaged "
                     "over the test scenarios both hold; all three intervals must lie above 0.", comps)


def claim2(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    area = area_values(curves, "avg_speed_kmh")
    final = final_values(curves, "avg_speed_kmh")
    comps = []
    for other in ("min", "coordinate"):
        o = model_label(other, True)
        comps.append(_compare(f"Proposed - {o}, area under training speed curve (km/h)",
                              _curve_diff(area, "proposed", other), min_seeds, 2))
        comps.append(_compare(f"Proposed - {o}, final training speed (km/h)",
                              _curve_diff(final, "proposed", other), min_seeds, 2))
    return _claim(2, "Learning speed = mean of the binned training speed curve up to the step every run "
                     "reached (normalised area); level = mean speed over each run's last 10 % of steps. "
                     "Proposed minus each other method; all four intervals must lie above 0.", comps)


def claim3(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    final = final_values(curves, "lane_changes")
    sc = _test_scenarios(evals)
    comps = []
    for other in ("min", "coordinate"):
        o = model_label(other, True)
        comps.append(_compare(f"{o} - Proposed, final training lane changes",
                              _curve_diff(final, other, "proposed"), min_seeds, 2))
        comps.append(_compare(f"{o} - Proposed, test lane changes",
                              _eval_diff(evals, other, "proposed", "lane_changes", sc), min_seeds, 2))
    return _claim(3, "Lane changes per episode of each other method minus proposed's, at the end of training "
                     "(last 10 % of steps) and in test (mean over scenarios); all intervals must lie above 0.", comps)


def claim4(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    fluct = fluctuation_values(curves, "overtakes")
    comps = [_compare(f"Min - {model_label(other, True)}, std of bin-to-bin change of overtakes",
                      _curve_diff(fluct, "min", other), min_seeds, 3)
             for other in ("proposed", "coordinate")]
    return _claim(4, "Fluctuation = standard deviation of the step-to-step changes of the binned training "
                     "overtake curve (as drawn in the overtakes figure), per seed. Min minus each other "
                     "method; both intervals must lie above 0.", comps)


def claim5(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    comps, notes = [], []
    for other in ("min", "coordinate"):
        o = model_label(other, True)
        for s in SCENARIOS:
            comps.append(_compare(f"Proposed - {o}, return in scenario {s}",
                                  _eval_diff(evals, "proposed", other, "episode_return", [s]), min_seeds, 1))
        poi = probability_of_improvement(per_scenario(evals, "proposed", "episode_return"),
                                         per_scenario(evals, other, "episode_return"))
        if not np.isnan(poi.point):
            notes.append(f"P(Proposed > {o}) over scenarios: {fmt(poi.point, digits=2)} (a point; no interval)")
    return _claim(5, "Mean test episode return of proposed minus each other method, separately in each of the "
                     "five scenarios; all ten intervals must lie above 0 (a missing scenario makes it inconclusive).",
                  comps, notes)


def _by_cv(evals: pd.DataFrame, model: str) -> dict[float, np.ndarray]:
    """Per-seed returns keyed by the scenario's connected-vehicle share (`cv_ratio`, as logged)."""
    ratio = evals.groupby(evals["scenario"].astype(str))["cv_ratio"].first().to_dict() if "cv_ratio" in evals \
        else PAPER_CV_RATIO
    return {float(ratio.get(s, PAPER_CV_RATIO[s])): v
            for s, v in per_scenario(evals, model, "episode_return", list(SCENARIOS)).items()}


def claim6(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    prop, mn = _by_cv(evals, "proposed"), _by_cv(evals, "min")
    rise = _compare("Proposed slope of return vs CV ratio (per unit ratio)", slope_ci(prop), min_seeds, 1)
    gap = _compare("Proposed slope - Min slope", slope_difference_ci(prop, mn), min_seeds, 1)
    min_slope = slope_ci(mn)
    flat_verdict, flat_reason = judge(min_slope, min_seeds)
    # "Flat" is the absence of a trend: a Min slope that ties with 0 is what the claim expects, an
    # interval clear of 0 in either direction contradicts it.
    label = "Min slope of return vs CV ratio (flat = interval covers 0)"
    if flat_verdict in (SUPPORTED, NOT_SUPPORTED):
        flat = Comparison(label, min_slope, NOT_SUPPORTED, "interval excludes 0: Min is not flat", 1)
    elif flat_verdict == TIE:
        flat = Comparison(label, min_slope, SUPPORTED, "interval covers 0", 1)
    else:
        flat = Comparison(label, min_slope, INCONCLUSIVE, flat_reason, 1)
    comps = [rise, flat, gap]
    notes = [] if len(prop) == 5 else [f"proposed evaluated in {len(prop)} of 5 scenarios"]
    return _claim(6, "Least-squares slope of the test return against the CV ratio (0 to 1), per seed (one "
                     "network tested in all five scenarios), then the interval over seeds. Supported if "
                     "proposed's slope lies above 0, Min's covers 0 (flat), and the slope difference lies "
                     "above 0 (so 'flat' is not just noise).", comps, notes)


def claim7(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int) -> ClaimResult:
    sc = _test_scenarios(evals)
    comps = [_compare("Proposed - Coordinate, test return (mean over scenarios)",
                      _eval_diff(evals, "proposed", "coordinate", "episode_return", sc), min_seeds, 1)]
    poi = probability_of_improvement(per_scenario(evals, "proposed", "episode_return", sc),
                                     per_scenario(evals, "coordinate", "episode_return", sc))
    notes = []
    if not np.isnan(poi.point):
        notes.append(f"P(Proposed > Coordinate): {fmt(poi.point, digits=2)} (a point; no interval)")
    return _claim(7, "Mean test episode return of proposed minus Coordinate, each seed averaged over the "
                     "scenarios first; the interval must lie above 0.", comps, notes)


CHECKS: dict[int, Callable[[pd.DataFrame, pd.DataFrame, int], ClaimResult]] = {
    1: claim1, 2: claim2, 3: claim3, 4: claim4, 5: claim5, 6: claim6, 7: claim7}


def evaluate_claims(evals: pd.DataFrame, curves: pd.DataFrame, min_seeds: int = MIN_SEEDS) -> list[ClaimResult]:
    """All seven claims, in the paper's order. They read the paper's three methods' training curves only:
    a variant beside them (a model of another name or budget) must not move a claim's numbers."""
    curves = curves[curves["model"].isin(LEARNED)] if "model" in curves else curves
    return [check(evals, curves, min_seeds) for check in CHECKS.values()]


def claims_table(results: list[ClaimResult]) -> pd.DataFrame:
    return pd.DataFrame([{"claim": r.number, "statement": r.statement, "verdict": r.verdict,
                          "evidence": "; ".join(c.text() for c in r.comparisons)} for r in results])


def _first(comparisons: list[Comparison], verdict: str) -> Comparison | None:
    return next((c for c in comparisons if c.verdict == verdict), None)


def verdict_sentence(result: ClaimResult) -> str:
    """What decides the verdict, in one sentence with the number behind it."""
    comps, total = result.comparisons, len(result.comparisons)
    of = f"of {total} difference{'s' if total != 1 else ''}"
    if result.verdict == SUPPORTED:
        # The difference closest to failing is the one worth quoting.
        closest = min(comps, key=lambda c: abs(c.estimate.low) if c.estimate.has_ci else np.inf)
        what = "its one difference lies" if total == 1 else f"all {total} differences it needs lie"
        return f"{what.capitalize()} above 0 (closest to 0: {closest.label}, {closest.number()})."
    if result.verdict == NOT_SUPPORTED:
        against = [c for c in comps if c.verdict == NOT_SUPPORTED]
        first = against[0]
        return f"The opposite holds in {len(against)} {of} ({first.label}, {first.number()})."
    if result.verdict == TIE:
        ties = [c for c in comps if c.verdict == TIE]
        held = sum(c.verdict == SUPPORTED for c in comps)
        first = ties[0]
        rest = "; the other one holds" if held == 1 else f"; the other {held} hold" if held else ""
        return (f"{len(ties)} {of} cannot be told from 0 with these seeds ({first.label}, {first.number()})"
                f"{rest}.")
    missing = _first(comps, INCONCLUSIVE)
    return f"Not decided: {missing.label}: {missing.reason}." if missing else "Not decided: no data."
