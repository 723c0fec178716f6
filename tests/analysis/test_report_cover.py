"""The report's first page and wording: its scale, a smoke run's banner, claims by number, and no
false coverage note (fast: no store, no PDF)."""

from __future__ import annotations

import pandas as pd

from analysis.claims import INCONCLUSIVE, NOT_SUPPORTED, SUPPORTED, ClaimResult
from analysis.discussion import discussion
from analysis.pipeline import _config_runs, _models_with_several_training_configs
from analysis.report import claim_numbers
from analysis.scale import is_smoke, models_phrase, scale_lines

SMOKE_CONFIG = """experiment: {name: smoke}
learner: {total_steps: 256}
observation: {height: 36, width: 36, frame_stack: 2}
eval: {checkpoint: final}
scenario: {name: '3'}
seed: 1
model: {learned: true}
"""


def _claims() -> list[ClaimResult]:
    verdicts = [NOT_SUPPORTED] * 4 + [INCONCLUSIVE] * 2 + [SUPPORTED]
    return [ClaimResult(n, f"claim {n}", v, "rule") for n, v in enumerate(verdicts, start=1)]


def test_scale_states_ours_beside_the_papers() -> None:
    evals = pd.DataFrame({"model": ["proposed"] * 3, "n_episodes": [4, 4, 8]})
    assert scale_lines({"proposed": SMOKE_CONFIG}, evals) == [
        "smoke (Proposed): 256 training steps per seed (paper 1,000,000); images 36x36, 2 frames (paper 84x84, 4); "
        "tested with the final checkpoint (paper: the final network); 4/8 test episodes per cell (paper: about 834)."]
    assert is_smoke({"proposed": SMOKE_CONFIG}) and not is_smoke({"proposed": "experiment: {name: quick}\n"})
    assert scale_lines({}, pd.DataFrame()) == ["Scale unknown: the runs logged no config."]


def test_scale_gives_each_preset_its_own_line_without_markup() -> None:
    variant = SMOKE_CONFIG.replace("smoke", "quick160").replace("256", "160000")
    human = "experiment: {name: smoke}\nmodel: {learned: false}\n"
    lines = scale_lines({"proposed": SMOKE_CONFIG, "proposed_enriched": variant, "human": human}, pd.DataFrame())
    assert [line.split(":")[0] for line in lines] == ["smoke (Proposed)", "quick160 (Variant"]
    assert lines[1].startswith("quick160 (Variant: enriched HGM): 160,000 training steps per seed")
    assert not any("`" in line for line in lines)
    assert len(scale_lines({"proposed": SMOKE_CONFIG, "human": human}, pd.DataFrame())) == 1


def test_a_preset_names_its_methods_and_the_kinds_of_their_forms() -> None:
    """The quick preset runs three methods in up to four forms each: page 1 names the methods and the kinds of
    form, not fourteen labels, so that the scale lines fit the page."""
    quick = ["proposed", "min", "coordinate", "proposed_guarded", "min_guarded", "coordinate_guarded",
             "proposed_layer_at_test", "min_layer_at_test", "proposed_safest", "coordinate_guarded_safest"]
    assert models_phrase(quick) == "Proposed, Min, Coordinate and their guarded, layer-at-test and safest forms"
    assert models_phrase(["proposed", "proposed_safest"]) == "Proposed and its safest form"
    assert models_phrase(["proposed", "min", "proposed_guarded", "proposed_guarded_safest"]) == \
        "Proposed, Min and Proposed's guarded and safest forms"
    # A form whose method the preset did not run keeps its label.
    assert models_phrase(["proposed", "min_guarded"]) == "Proposed, Min (guarded)"
    assert models_phrase(["proposed_guarded"]) == "Proposed (guarded)"
    assert models_phrase(["proposed", "min", "my_variant"]) == "Proposed, Min, my_variant"
    configs = {m: SMOKE_CONFIG for m in quick}
    assert scale_lines(configs, pd.DataFrame())[0].startswith(
        "smoke (Proposed, Min, Coordinate and their guarded, layer-at-test and safest forms): 256 training steps")


def test_claims_are_listed_by_number_never_as_a_count() -> None:
    claims = _claims()
    assert claim_numbers(claims, SUPPORTED) == "claim 7"
    assert claim_numbers(claims, NOT_SUPPORTED) == "claims 1, 2, 3 and 4"
    assert claim_numbers(claims, INCONCLUSIVE) == "claims 5 and 6"
    assert claim_numbers(claims[:4], SUPPORTED) == "none"
    first = discussion(claims, pd.DataFrame(), 1, pd.DataFrame())[0]
    assert first.startswith("Of the paper's seven claims, our runs support one claim (7), contradict four claims "
                            "(1, 2, 3 and 4), find a tie in none and leave two claims (5 and 6) undecided.")


def test_seeds_alone_are_not_several_training_configs() -> None:
    """A train_key includes the seed: five seeds of one config are five keys and no warning."""
    runs = pd.DataFrame({"stage": ["train"] * 4 + ["eval"], "model": ["proposed", "proposed", "min", "min", "min"],
                         "seed": [0, 1, 0, 0, 0], "train_key": ["a", "b", "c", "d", "x"]})
    assert _models_with_several_training_configs(runs) == ["min"]  # min's seed 0: two keys
    assert _models_with_several_training_configs(runs[runs["model"] == "proposed"]) == []


def test_the_printed_config_says_which_run_it_is_from() -> None:
    assert _config_runs({"proposed": SMOKE_CONFIG}) == {
        "proposed": "of one evaluation run, scenario 3, seed 1; its other runs differ in scenario and seed only"}
