"""research/studies/one_action.py: a host that takes one action in every decision, tested as the app tests."""

from __future__ import annotations

import pandas as pd
import pytest

from hgm_repro.simulator import Action
from research.tests.studies import load_study


def _module():
    return load_study("one_action")


def test_a_host_that_always_accelerates_crashes_in_every_episode_and_its_traffic_repeats() -> None:
    study = _module()
    job = study.job_for("smoke", 3, 0)
    first = study.one_action_return(job, Action.ACCELERATE)
    assert first["collisions"] == 1.0 and first["avg_speed_kmh"] > 70
    assert study.one_action_return(job, Action.ACCELERATE) == first
    # Another seed draws other test traffic.
    assert study.one_action_return(study.job_for("smoke", 3, 1), Action.ACCELERATE) != first


def test_each_model_is_compared_with_the_one_action_host_of_its_own_scenario_and_seed(tmp_path) -> None:
    study = _module()
    accelerate = study.one_action_return(study.job_for("smoke", 3, 0), Action.ACCELERATE)["episode_return"]
    evals = pd.DataFrame({"experiment": ["smoke", "smoke", "quick"], "model": ["min", "proposed", "min"],
                          "scenario": 3, "seed": 0, "episode_return": [accelerate, accelerate + 5.0, 99.0]})
    table = study.compare(evals, "smoke", ["min", "proposed"], Action.ACCELERATE)
    assert len(table) == 1
    row = table.iloc[0]
    assert row["min_difference"] == pytest.approx(0.0) and row["proposed_difference"] == pytest.approx(5.0)
    with pytest.raises(SystemExit, match="no test of \\['coordinate'\\] in experiment 'smoke'"):
        study.compare(evals, "smoke", ["coordinate"], Action.ACCELERATE)
