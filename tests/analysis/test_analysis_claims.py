"""Claim verdicts and the statistics behind them, on synthetic data whose answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.claims import (
    INCONCLUSIVE,
    NOT_SUPPORTED,
    SUPPORTED,
    TIE,
    combine,
    evaluate_claims,
    judge,
)
from analysis.curves import fluctuation_values
from analysis.stats import (
    Estimate,
    difference_ci,
    iqm,
    mean_ci,
    probability_of_improvement,
    slope_ci,
)
from analysis.synthetic import SyntheticSpec, synthetic_frames

FIVE = (0, 1, 2, 3, 4)


def _verdicts(spec: SyntheticSpec) -> dict[int, str]:
    evals, curves, _ = synthetic_frames(spec)
    return {r.number: r.verdict for r in evaluate_claims(evals, curves)}


def test_every_claim_supported_when_the_data_has_every_effect() -> None:
    assert _verdicts(SyntheticSpec(seeds=FIVE)) == {k: SUPPORTED for k in range(1, 8)}


def test_every_claim_not_supported_when_the_data_has_the_opposite_effects() -> None:
    spec = SyntheticSpec(
        seeds=FIVE,
        return_base={"proposed": 1800.0, "min": 1850.0, "coordinate": 1900.0, "human": 1500.0},
        return_slope={"proposed": -60.0, "min": 80.0, "coordinate": 0.0, "human": 0.0},
        speed={"proposed": 60.0, "min": 62.0, "coordinate": 64.0, "human": 70.0},
        lane_changes={"proposed": 6.0, "min": 3.0, "coordinate": 2.0, "human": 8.0},
        tau={"proposed": 0.4, "min": 0.1, "coordinate": 0.1},
        overtake_wiggle={"proposed": 1.5, "min": 0.1, "coordinate": 1.5},
    )
    assert _verdicts(spec) == {k: NOT_SUPPORTED for k in range(1, 8)}


def test_every_claim_inconclusive_with_too_few_seeds() -> None:
    assert _verdicts(SyntheticSpec(seeds=(0, 1))) == {k: INCONCLUSIVE for k in range(1, 8)}


def test_every_claim_a_tie_when_methods_do_not_differ() -> None:
    same = {"proposed": 70.0, "min": 70.0, "coordinate": 70.0, "human": 70.0}
    spec = SyntheticSpec(
        seeds=FIVE, noise=0.0, curve_noise=0.0,
        return_base={k: 1900.0 for k in same}, return_slope={k: 0.0 for k in same},
        speed=same, lane_changes={k: 3.0 for k in same}, overtakes={k: 6.0 for k in same},
        tau={"proposed": 0.2, "min": 0.2, "coordinate": 0.2},
    )
    assert _verdicts(spec) == {k: TIE for k in range(1, 8)}


def test_missing_method_makes_its_claims_inconclusive() -> None:
    verdicts = _verdicts(SyntheticSpec(seeds=FIVE, models=("proposed", "min", "coordinate")))
    assert verdicts[1] == INCONCLUSIVE  # no human-driven host
    assert verdicts[7] == SUPPORTED


def test_a_variant_trained_longer_moves_no_claim() -> None:
    # A variant beside the grid (another name, twice the steps, curves of its own) is tabled and drawn,
    # never judged: every claim's evidence stays the same to the digit (claim 4 once moved, because
    # its curves were binned on a grid as long as the longest run of any model).
    spec = SyntheticSpec(seeds=FIVE)
    evals, curves, _ = synthetic_frames(spec)
    v_evals, v_curves, _ = synthetic_frames(SyntheticSpec(seeds=FIVE, models=("proposed",),
                                                          total_steps=2 * spec.total_steps, rng_seed=3))
    v_evals, v_curves = (f.assign(model="proposed_enriched", run_id="v" + f["run_id"].astype(str))
                         for f in (v_evals, v_curves))
    alone = evaluate_claims(evals, curves)
    beside = evaluate_claims(pd.concat([evals, v_evals]), pd.concat([curves, v_curves]))
    assert [(r.verdict, [c.text() for c in r.comparisons]) for r in beside] == \
        [(r.verdict, [c.text() for c in r.comparisons]) for r in alone]


def test_fluctuation_of_a_run_does_not_depend_on_other_models_runs() -> None:
    _, curves, _ = synthetic_frames(SyntheticSpec(seeds=(0, 1), models=("proposed", "min")))
    longer = curves[curves["model"] == "min"].assign(model="other", step=lambda f: f["step"] * 3)
    alone = fluctuation_values(curves, "overtakes")
    beside = fluctuation_values(pd.concat([curves, longer]), "overtakes")
    pd.testing.assert_frame_equal(beside[beside["model"] != "other"].reset_index(drop=True), alone)


def test_judge_rule() -> None:
    assert judge(Estimate(1.0, 0.5, 1.5, 5)) == (SUPPORTED, "interval above 0")
    assert judge(Estimate(-1.0, -1.5, -0.5, 5))[0] == NOT_SUPPORTED
    assert judge(Estimate(0.2, -0.5, 0.9, 5)) == (TIE, "interval covers 0")
    assert judge(Estimate(1.0, np.nan, np.nan, 1)) == (INCONCLUSIVE, "1 seed: no confidence interval")
    assert judge(Estimate(1.0, 0.5, 1.5, 2))[0] == INCONCLUSIVE  # below MIN_SEEDS
    assert judge(Estimate(np.nan, np.nan, np.nan, 0)) == (INCONCLUSIVE, "missing data")


def test_combine_rule() -> None:
    assert combine([SUPPORTED, SUPPORTED]) == SUPPORTED
    assert combine([SUPPORTED, INCONCLUSIVE]) == INCONCLUSIVE
    assert combine([SUPPORTED, TIE]) == TIE
    assert combine([TIE, INCONCLUSIVE]) == INCONCLUSIVE
    assert combine([SUPPORTED, TIE, NOT_SUPPORTED]) == NOT_SUPPORTED
    assert combine([]) == INCONCLUSIVE


def test_probability_of_improvement_known_values() -> None:
    better = {"1": [5.0, 6.0, 7.0], "2": [5.0, 6.0]}
    worse = {"1": [1.0, 2.0], "2": [1.0, 2.0, 3.0]}
    est = probability_of_improvement(better, worse)
    assert est.point == 1.0 and not est.has_ci  # a point: no interval for it covers at five seeds
    assert probability_of_improvement(worse, better).point == 0.0
    assert probability_of_improvement(better, better).point == pytest.approx(0.5)
    # Half the pairs win: x = {0, 2} vs y = {1}.
    assert probability_of_improvement({"a": [0.0, 2.0]}, {"a": [1.0]}).point == pytest.approx(0.5)


def test_intervals_over_seeds() -> None:
    one = mean_ci([3.0])
    assert one.point == 3.0 and not one.has_ci and one.n == 1
    est = mean_ci([1.0, 2.0, 3.0, 4.0, 5.0])
    assert est.point == 3.0 and 1.0 <= est.low < 3.0 < est.high <= 5.0
    diff = difference_ci({"1": [10.0, 11.0, 12.0], "2": [20.0, 21.0, 22.0]}, {"1": [0.0, 1.0, 2.0]})
    assert diff.point == pytest.approx(10.0)  # only the scenario both hold is compared
    assert iqm([0.0, 1.0, 2.0, 3.0, 100.0, -100.0, 1.5, 2.5]) == pytest.approx(1.75)


def test_slope_of_exact_line() -> None:
    line = {x: [10.0 + 40.0 * x, 10.0 + 40.0 * x, 10.0 + 40.0 * x] for x in (0.0, 0.25, 0.5, 0.75, 1.0)}
    est = slope_ci(line)
    assert est.point == pytest.approx(40.0) and est.low == pytest.approx(40.0) and est.high == pytest.approx(40.0)
