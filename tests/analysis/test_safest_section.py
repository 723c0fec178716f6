"""The report's section on the safest network: each host's safest tests beside the same trainings' tests of
the preset's network, paired seed by seed, and the trainings that have no safest test named."""

from __future__ import annotations

import pandas as pd
import pytest

from analysis import safest
from analysis.labels import SAFEST, model_label


def rows(model: str, returns: dict[int, float], collisions: dict[int, float], scenarios=("3", "1")) -> list[dict]:
    # Scenario 1 earns 10 less than scenario 3 on every seed: the mean over scenarios is the scenario-3 value - 5.
    return [{"model": model, "scenario": s, "seed": seed, "episode_return": r - (10 if s == "1" else 0),
             "collisions": collisions[seed]} for s in scenarios for seed, r in returns.items()]


def evals() -> pd.DataFrame:
    return pd.DataFrame([
        *rows("proposed", {0: 250, 1: 240, 2: 230}, {0: 0.2, 1: 0.3, 2: 0.1}),
        # seed 2 has no safe pass: no safest test.
        *rows("proposed_safest", {0: 230, 1: 236}, {0: 0.02, 1: 0.04}),
        *rows("human", {0: 220, 1: 220, 2: 220}, {0: 0.0, 1: 0.0, 2: 0.0}),
    ])


def test_safest_names_pair_with_the_hosts_they_were_chosen_for():
    assert SAFEST["proposed_safest"] == "proposed" and SAFEST["min_guarded_safest"] == "min_guarded"
    assert "safest" in model_label("coordinate_guarded_safest")


def test_the_difference_pairs_the_seeds_tested_both_ways():
    diff = safest.paired(evals(), "proposed", "episode_return", "3")
    assert diff.n == 2 and diff.point == pytest.approx(((230 - 250) + (236 - 240)) / 2)
    crashes = safest.paired(evals(), "proposed", "collisions", None)
    assert crashes.point == pytest.approx(((0.02 - 0.2) + (0.04 - 0.3)) / 2)
    assert safest.paired(evals(), "human", "episode_return", "3").n == 0


def test_the_table_puts_each_safest_row_under_its_host_and_the_section_names_the_missing_seed():
    table = safest.table(evals())
    assert [r[:2] for r in table[1:]] == [["Proposed", "its preset's (best.pt)"], ["Proposed", "safest"]]
    assert table[1][2].startswith("240.0 [") and table[1][-1] == "3"
    assert table[2][2].startswith("233.0 [") and table[2][4].startswith("228.0 [") and table[2][-1] == "2"
    said = safest.sentences(evals())
    assert len(said) == 1 and "Seed 2 has no safest test" in said[0] and "over the 2 seeds" in said[0]
    section = safest.section(evals())
    assert section is not None and section.title == safest.TITLE
    plain = evals()
    assert safest.section(plain[plain["model"] != "proposed_safest"]) is None
    runs = pd.DataFrame({"model": ["proposed_safest", "proposed"], "stage": ["eval", "eval"],
                         safest.BAR_PARAM: ["0.05", "0.05"]})
    assert safest.bars(runs) == ["0.05"]
    assert "under 0.05 collisions per episode" in safest.section(evals(), runs).blocks[0].text


def test_the_first_table_lists_hosts_and_leaves_the_probes_to_their_sections():
    from analysis.markdown import headline_lines

    text = "\n".join(headline_lines(evals(), ["1", "3"]))
    assert "| Proposed |" in text and "| Human |" in text and "safest" not in text


def test_refused_trainings_are_read_from_the_training_runs_and_named_even_when_a_host_has_no_safest_test():
    tested = pd.concat([evals(), pd.DataFrame(rows("coordinate", {0: 200, 1: 190}, {0: 0.5, 1: 0.6}))])
    tested["train_key"] = tested["model"].str.replace("_safest", "") + tested["seed"].astype(str)
    runs = pd.DataFrame({
        "stage": ["train"] * 5 + ["eval"],
        "model": ["proposed", "proposed", "coordinate", "coordinate", "coordinate", "coordinate"],
        "seed": [2, 0, 0, 1, 7, 0],
        "train_key": ["proposed2", "proposed0", "coordinate0", "coordinate1", "coordinate7", "coordinate0"],
        "safest_choice": ["refused", "20000", "refused", "refused", "refused", None],
        "safest_bar": ["0.05"] * 5 + [None],
        "safest_lowest_collisions": ["0.1170", "0.0100", "0.0600", "0.5000", "0.9000", None],
    })
    refused = safest.refusals(tested, runs)
    # proposed seed 0 was chosen; coordinate seed 7 is no training the tests used (another preset, say).
    assert refused[["host", "seed"]].values.tolist() == [["proposed", 2], ["coordinate", 0], ["coordinate", 1]]
    said = safest.sentences(tested, refused)
    assert said[0].startswith("Proposed: the safest network minus best.pt")
    assert "seed 2 was refused: no kept pass stayed under 0.05 collisions per episode" in said[0]
    assert "0.117 times per episode" in said[0] and "no safest test yet" not in said[0]
    assert said[1].startswith("Coordinate: no safest test; seeds 0, 1 were refused")
    assert "0.060-0.500 times per episode" in said[1]
    # A host whose every training was refused still gets the section; without runs nothing is refused.
    alone = tested[tested["model"] != "proposed_safest"]
    section = safest.section(alone, runs)
    assert section is not None and any("Coordinate: no safest test" in getattr(b, "text", "") for b in section.blocks)
    assert safest.section(alone) is None and safest.refusals(tested, None).empty
