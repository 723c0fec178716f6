"""research/studies/study_report.py's table: the per-seed cells, the bar count against each seed's human-driven
host, and rows taken from an earlier report's CSV."""

from __future__ import annotations

import sys

import pandas as pd
import pytest

from tests.helpers import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "research" / "studies"))
import study_report  # noqa: E402 - research/studies/ is a folder of scripts, not a package


def _rows(arm: str, returns: list[float], collisions: list[float], seeds=(100, 101, 102)) -> list[dict]:
    return [{"arm": arm, "seed": s, "episode_return": r, "collisions": c, "dangerous_actions": 0.0,
             "avg_speed_kmh": 50.0, "lane_changes": 0.0, "overtakes": 0.0}
            for s, r, c in zip(seeds, returns, collisions, strict=True)]


def test_the_table_counts_a_seed_only_when_it_beats_that_seeds_human_host_under_0_2_collisions(tmp_path):
    results = pd.DataFrame(_rows("human", [240, 220, 230], [0, 0, 0])
                           # beats 240 safely; beats 220 but crashes 0.2 (not under); below 230
                           + _rows("r20_all@best", [241, 300, 229], [0.1, 0.2, 0.0]))
    earlier = tmp_path / "learner_study_per_seed.csv"
    results.to_csv(earlier, index=False)
    study_report.report([], tmp_path / "out", study_report.earlier_results(earlier, ["human", "r20_all@best"]))
    table = (tmp_path / "out" / "learner_study_table.md").read_text().splitlines()
    (row,) = [line for line in table if line.startswith("| `r20_all@best`")]
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1:4] == ["241, 0.10", "300, 0.20", "229, 0.00"]
    assert cells[-1] == "1 of 3"
    # The mean, its 95 % Student-t interval (sd 38.0 over 3 seeds: 256.7 +- 4.303 * 38.0 / sqrt(3)) and the IQM
    # (3 seeds: none trimmed).
    assert cells[4] == "257 [162, 351], 257"


def test_a_budget_cut_row_stands_in_the_table_with_the_arms_own_rows_and_says_what_it_tested(tmp_path):
    """research/studies/budget_cut.py writes ARM@best80k rows (best.pt among the passes up to 80k): the report keeps
    them (a summary limited to the known suffixes dropped them), beside the arm's own rows and before the
    reference hosts, and its overrides name the cut."""
    results = pd.DataFrame(_rows("human", [240, 220, 230], [0, 0, 0]) + _rows("r20_all_160k@best", [250, 230, 240],
                                                                             [0.1, 0.0, 0.0])
                           + _rows("r20_all_160k@best80k", [200, 230, 231], [0.3, 0.1, 0.0]))
    earlier = tmp_path / "learner_study_per_seed.csv"
    results.to_csv(earlier, index=False)
    arms = ["human", "r20_all_160k@best", "r20_all_160k@best80k"]
    study_report.report([], tmp_path / "out", study_report.earlier_results(earlier, arms))
    summary = pd.read_csv(tmp_path / "out" / "learner_study_summary.csv").set_index("arm")
    assert list(summary.index) == ["r20_all_160k@best", "r20_all_160k@best80k", "human"]
    assert summary.loc["r20_all_160k@best80k", "seeds_beating_human_under_0.2"] == 2
    assert "passes up to 80k env steps" in summary.loc["r20_all_160k@best80k", "overrides"]
    assert summary.loc["r20_all_160k@best", "overrides"].endswith("eval.checkpoint=best")
    table = (tmp_path / "out" / "learner_study_table.md").read_text()
    assert "| `r20_all_160k@best80k` | 200, 0.30 | 230, 0.10 | 231, 0.00 |" in table


def test_a_learned_arm_with_a_blank_frame_test_says_so_and_a_reference_host_does_not(tmp_path):
    """A row tested only by the evaluation of before the blank-frame fix (evaluation version 1) is marked
    in the table and the summary, if it is a learned arm's: the reference hosts read the simulator."""
    rows = (_rows("human", [240, 220, 230], [0, 0, 0]) + _rows("r20_all@best", [241, 300, 229], [0.1, 0.2, 0.0])
            + _rows("r20_all", [200, 210, 220], [0.3, 0.3, 0.3]))
    results = pd.DataFrame(rows).assign(evaluation_version=[1, 1, 1, 2, 1, 2, 2, 2, 2])
    earlier = tmp_path / "learner_study_per_seed.csv"
    results.to_csv(earlier, index=False)
    study_report.report([], tmp_path / "out", study_report.earlier_results(earlier, ["human", "r20_all@best",
                                                                                      "r20_all"]))
    table = (tmp_path / "out" / "learner_study_table.md").read_text()
    assert "| `r20_all@best` (blank-frame test) | 241, 0.10 |" in table
    assert "| `r20_all` | 200, 0.30 |" in table and "| `human` | 240, 0.00 |" in table
    summary = pd.read_csv(tmp_path / "out" / "learner_study_summary.csv").set_index("arm")
    assert summary["blank_frame_test"].to_dict() == {"r20_all": False, "r20_all@best": True, "human": False}


def test_an_arm_the_earlier_report_lacks_is_refused_by_name(tmp_path):
    earlier = tmp_path / "learner_study_per_seed.csv"
    pd.DataFrame(_rows("human", [240, 220, 230], [0, 0, 0])).to_csv(earlier, index=False)
    with pytest.raises(SystemExit, match=r"no rows for \['r20_all'\]"):
        study_report.earlier_results(earlier, ["r20_all"])


def test_earlier_rows_come_from_several_files_the_first_file_winning_a_seed(tmp_path):
    first, second = tmp_path / "a.csv", tmp_path / "b.csv"
    pd.DataFrame(_rows("human", [240, 220, 230], [0, 0, 0])).to_csv(first, index=False)
    pd.DataFrame(_rows("human", [1, 1, 1], [0, 0, 0]) + _rows("r20_all@best80k", [10, 20, 30], [1, 1, 1])).to_csv(
        second, index=False)
    rows = study_report.earlier_results([first, second], ["human", "r20_all@best80k"]).set_index(["arm", "seed"])
    assert list(rows.loc["human"]["episode_return"]) == [240, 220, 230]
    assert list(rows.loc["r20_all@best80k"]["episode_return"]) == [10, 20, 30]
    with pytest.raises(SystemExit, match=r"a.csv, .*b.csv has no rows for \['r20_all'\]"):
        study_report.earlier_results([first, second], ["r20_all"])


def test_an_earlier_row_fills_only_the_seeds_the_store_lacks(tmp_path):
    earlier = tmp_path / "learner_study_per_seed.csv"
    pd.DataFrame(_rows("human", [240, 220, 230], [0, 0, 0]) + _rows("r20_all", [10, 20, 30], [1, 1, 1])).to_csv(
        earlier, index=False)
    # A store's re-run of seed 100 (here given as the earlier frame's first rows, which the store's are).
    store_like = pd.DataFrame(_rows("r20_all", [99], [0.5], seeds=(100,)))
    merged = pd.concat([store_like, study_report.earlier_results(earlier, ["human", "r20_all"])], ignore_index=True)
    study_report.report([], tmp_path / "out", merged)
    per_seed = pd.read_csv(tmp_path / "out" / "learner_study_per_seed.csv").set_index(["arm", "seed"])
    assert per_seed.loc[("r20_all", 100), "episode_return"] == 99
    assert list(per_seed.loc["r20_all"]["episode_return"]) == [99, 20, 30]


def test_an_arm_that_chooses_another_model_is_matched_on_that_model_and_its_own_config():
    # r20_min_160k names only model=min; Min's config also turns the HGM stream off, which the run logs
    signatures = study_report.arm_signatures()
    min_arm = signatures["r20_min_160k"]
    assert min_arm["model"] == "min" and min_arm["model.streams.hgm"] == "none"
    assert signatures["r20_all"]["model"] == "proposed"
    run = {key: str(value) for key, value in min_arm.items()}
    assert study_report._arm_of(run, signatures) == "r20_min_160k"
    assert study_report._arm_of({**run, "model": "coordinate"}, signatures) == "r20_coordinate_160k"
    assert study_report._arm_of({**run, "model": "proposed"}, signatures) is None  # its HGM is on
