"""Each scenario's traffic mix as its evaluation runs logged it (`analysis/scenarios.py`)."""

from __future__ import annotations

import pandas as pd

from analysis.claims import _by_cv
from analysis.scenarios import PAPER_CV_RATIO, cv_ratios, scenario_mix, with_cv_ratio


def _runs(rows: list[tuple[str, str, float, float, float]]) -> pd.DataFrame:
    return pd.DataFrame([{"stage": stage, "scenario": name, "params.scenario.ratios.NCV": ncv,
                          "params.scenario.ratios.AHV": ahv, "params.scenario.ratios.CHV": chv}
                         for stage, name, ncv, ahv, chv in rows])


def test_the_mix_comes_from_the_evaluation_runs_params():
    runs = _runs([("eval", "3", 0.4, 0.4, 0.2), ("eval", "mine", 0.9, 0.05, 0.05), ("train", "train", 0.5, 0.25, 0.25)])
    mix = scenario_mix(runs)
    assert mix.loc["3"].tolist() == [0.4, 0.4, 0.2] and "train" not in mix.index
    ratios = cv_ratios(runs)
    assert ratios["3"] == 0.4 and ratios["mine"] == 0.9 and ratios["5"] == PAPER_CV_RATIO["5"]  # 5 logged nothing
    evals = with_cv_ratio(pd.DataFrame({"scenario": ["3", "mine", "7"]}), runs)
    assert evals["cv_ratio"].tolist()[:2] == [0.4, 0.9] and pd.isna(evals["cv_ratio"].iloc[2])


def test_runs_without_logged_mix_fall_back_to_table_5_and_claims_use_the_logged_share():
    assert scenario_mix(pd.DataFrame({"stage": ["eval"], "scenario": ["1"]})).empty
    assert cv_ratios(None) == PAPER_CV_RATIO
    # Per-seed values (each seed is one network tested in every scenario: comparisons pair them).
    evals = pd.DataFrame({"model": ["proposed"] * 2, "scenario": ["1", "2"], "seed": [0, 0],
                          "episode_return": [1.0, 2.0], "cv_ratio": [0.1, 0.3]})
    assert sorted(_by_cv(evals, "proposed")) == [0.1, 0.3]


def test_the_scene_pictures_carry_the_share_of_the_scenario_they_were_drawn_from():
    from analysis.pictures import scenario_pictures

    pictures, note = scenario_pictures(["1", "3"])
    assert note is None  # the pictures are skipped with a note on any failure: none here
    assert [(p.scenario, p.cv_ratio) for p in pictures] == [("1", 0.0), ("3", 0.5)]
