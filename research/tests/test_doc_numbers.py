"""The numbers research/results-narrative.md tells in words are the committed results bundle's: its test
table and the scenario-3 seeds it quotes are checked against docs/results, so that a re-run grid
cannot leave the narrative behind unnoticed."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from analysis.load import at_main_experiments
from analysis.tables import summary
from tests.helpers import REPO_ROOT

NARRATIVE = REPO_ROOT / "research" / "results-narrative.md"
BUNDLE = REPO_ROOT / "docs" / "results"
# The narrative's row labels and the models they stand for.
ROWS = {"Proposed (HGM + camera)": "proposed", "Min (camera)": "min", "Coordinate (camera + V2X list)": "coordinate",
        "Human-driven host": "human", "IDM + MOBIL": "idm_mobil",
        "IDM + MOBIL inside the host's limits": "idm_mobil_limits",
        "Variant: enriched HGM, 160k steps (not the paper's)": "proposed_enriched"}


def _evals() -> pd.DataFrame:
    # The grid's rows: a rung of the scale ladder publishes its runs of the same models beside them.
    return at_main_experiments(pd.read_csv(BUNDLE / "evals.csv", dtype={"scenario": str}))


def _table_rows(text: str) -> dict[str, list[str]]:
    """The narrative's test-return table: row label -> its five scenario cells."""
    section = text.split("## Test results", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] in ROWS:
            rows[cells[0]] = cells[1:]
    return rows


@pytest.mark.skipif(not (BUNDLE / "evals.csv").is_file(), reason="no committed results bundle")
def test_the_narratives_test_table_is_the_bundles_to_the_digit():
    table = summary(_evals(), ("episode_return",)).set_index(["model", "scenario"])
    rows = _table_rows(NARRATIVE.read_text())
    assert set(rows) == set(ROWS)
    for label, cells in rows.items():
        assert len(cells) == 5, label
        for scenario, cell in zip("12345", cells, strict=True):
            mean, low, high = (float(x) for x in re.match(r"(-?\d+) \[(-?\d+), (-?\d+)\]", cell).groups())
            want = table.loc[(ROWS[label], scenario)]
            for shown, exact in ((mean, want["mean"]), (low, want["low"]), (high, want["high"])):
                assert abs(shown - exact) <= 0.5 + 1e-9, (label, scenario, cell, exact)


# The sentences that quote scenario 3 seed by seed, and the model each quotes.
PER_SEED_SENTENCES = {"Per seed": "proposed", "Variant per seed": "proposed_enriched"}


@pytest.mark.skipif(not (BUNDLE / "evals.csv").is_file(), reason="no committed results bundle")
@pytest.mark.parametrize("opening", sorted(PER_SEED_SENTENCES))
def test_the_scenario_3_seeds_the_narrative_quotes_are_the_bundles(opening: str):
    model = PER_SEED_SENTENCES[opening]
    evals = _evals()
    s3 = evals[evals["scenario"] == "3"].set_index(["model", "seed"])
    text = " ".join(NARRATIVE.read_text().split())
    quoted = re.search(rf"(?<![A-Za-z]){opening}: ([\d, ]+) against ([\d, ]+), with ([\d., ]+) collisions", text)
    assert quoted, f"the narrative's sentence '{opening}: ...' for scenario 3 is gone"
    returns, human, collisions = ([float(x) for x in g.replace(",", " ").split()] for g in quoted.groups())
    for seed in range(5):
        assert abs(returns[seed] - s3.loc[(model, seed), "episode_return"]) <= 0.5
        assert abs(human[seed] - s3.loc[("human", seed), "episode_return"]) <= 0.5
        assert abs(collisions[seed] - s3.loc[(model, seed), "collisions"]) <= 0.005 + 1e-9


# The sentences that quote scenario 3's test-noise margins over the human-driven host, and the model each quotes.
MARGIN_SENTENCES = {"paper-HGM margins on seeds 0-4": "proposed", "variant margins on seeds 0-4": "proposed_enriched"}


@pytest.mark.skipif(not (BUNDLE / "episodes.csv").is_file(), reason="no committed results bundle")
@pytest.mark.parametrize("opening", sorted(MARGIN_SENTENCES))
def test_the_test_noise_margins_the_narrative_quotes_are_the_bundles(opening: str):
    from analysis.tables import seed_margins

    evals = _evals()
    episodes = pd.read_csv(BUNDLE / "episodes.csv", dtype={"scenario": str})
    margins = seed_margins(evals, episodes[episodes["run_id"].isin(set(evals["run_id"]))])
    model = MARGIN_SENTENCES[opening]
    mine = margins[(margins["model"] == model) & (margins["scenario"] == "3")].set_index("seed")
    text = " ".join(NARRATIVE.read_text().split())
    quoted = re.search(rf"(?<![A-Za-z]){opening}: ((?:-?\d+ \[-?\d+, -?\d+\](?:, )?){{5}}) \((\d) close\)", text)
    assert quoted, f"the narrative's test-noise margins '{opening}: ...' for scenario 3 are gone"
    cells = re.findall(r"(-?\d+) \[(-?\d+), (-?\d+)\]", quoted.group(1))
    for seed, cell in enumerate(cells):
        want = mine.loc[seed, ["margin", "margin_low", "margin_high"]].to_numpy(float)
        assert all(abs(float(x) - w) <= 0.5 + 1e-9 for x, w in zip(cell, want, strict=True)), (seed, cell, want)
    assert int(quoted.group(2)) == int(mine["close"].sum())


STUDY = REPO_ROOT / "research" / "study.md"


def _study_section(number: str) -> str:
    """research/study.md's section `number`, up to the next section."""
    return STUDY.read_text().split(f"\n## {number}. ", 1)[1].split("\n## ", 1)[0]


def _margin_cell(row: pd.Series) -> str:
    """A test-length table's cell: a seed's margin over the human-driven host [95% interval], collisions."""
    return f"{row['margin']:.0f} [{row['margin_low']:.0f}, {row['margin_high']:.0f}], {row['collisions']:.2f}"
# Each study section's tables that the study report wrote, as (section, the report's file).
STUDY_TABLES = [("10", REPO_ROOT / "research" / "study" / "r20_arms" / "learner_study_table.md"),
                ("11", REPO_ROOT / "research" / "study" / "r20_enriched_160k" / "learner_study_table.md"),
                ("12", REPO_ROOT / "research" / "study" / "r20_methods_160k" / "learner_study_table.md"),
                ("14", REPO_ROOT / "research" / "study" / "r20_reselect" / "learner_study_table.md"),
                ("15", REPO_ROOT / "research" / "study" / "r20_paper160" / "learner_study_table.md"),
                ("15", REPO_ROOT / "research" / "study" / "r20_methods_160k_v2" / "learner_study_table.md")]


@pytest.mark.parametrize(("section", "path"), STUDY_TABLES, ids=[f"{s}-{p.parent.name}" for s, p in STUDY_TABLES])
def test_a_study_sections_table_is_the_one_the_study_report_wrote(section: str, path):
    if not path.is_file():
        pytest.skip(f"no committed study table {path.name} for section {section}")
    text = _study_section(section)
    assert path.read_text().strip() in text, f"research/study.md section {section}'s table differs from {path}"


TEST_LENGTH = REPO_ROOT / "research" / "study" / "test_length" / "margins.csv"
PUBLISHED_BEFORE_FIX = TEST_LENGTH.parent / "published_before_fix.csv"


@pytest.mark.skipif(not TEST_LENGTH.is_file(), reason="no committed test-length study")
def test_the_test_length_sections_table_is_its_csv_and_its_short_test_is_the_published_one():
    study = pd.read_csv(TEST_LENGTH)
    mine = study[study["model"] == "proposed_enriched"]
    text = _study_section("13")


    by_test = {test: part.set_index("seed") for test, part in mine.groupby("test")}
    for seed in by_test["preset"].index:
        cells = [_margin_cell(by_test[test].loc[seed]) for test in ("preset", "long")]
        assert f"| {seed} | " + " | ".join(cells) + " |" in text, seed
    # The re-test's first episodes are the preset's test: they must give the numbers published then (before
    # the evaluation fix; docs/results has been published again since, and that bundle's rows are kept).
    published = pd.read_csv(PUBLISHED_BEFORE_FIX, dtype={"scenario": str})
    published = published[(published["model"] == "proposed_enriched") & (published["scenario"] == "3")]
    both = by_test["preset"].join(published.set_index("seed"), rsuffix="_published", how="inner")
    assert len(both) == len(by_test["preset"])
    for column in ("episode_return", "ref_return", "collisions"):
        assert (both[column] - both[f"{column}_published"]).abs().max() < 1e-3, column


TEST_LENGTH_V2 = REPO_ROOT / "research" / "study" / "test_length_v2" / "margins.csv"


@pytest.mark.skipif(not (TEST_LENGTH.is_file() and TEST_LENGTH_V2.is_file()), reason="no committed re-tests")
def test_the_fixed_re_tests_table_is_both_csvs_and_the_human_host_did_not_move():
    """Section 14: the published variant networks before and after the blank-frame fix. The human-driven
    host reads the simulator, not observations: its test must not move by a digit."""
    before, after = (pd.read_csv(path) for path in (TEST_LENGTH, TEST_LENGTH_V2))
    text = _study_section("14")


    tables = {(when, test): part.set_index("seed") for when, frame in (("before", before), ("after", after))
              for test, part in frame[frame["model"] == "proposed_enriched"].groupby("test")}
    for seed in tables["before", "preset"].index:
        cells = [_margin_cell(tables[when, test].loc[seed])
                 for test in ("preset", "long") for when in ("before", "after")]
        assert f"| {seed} | " + " | ".join(cells) + " |" in text, seed
    for test in ("preset", "long"):
        assert (tables["before", test]["ref_return"] - tables["after", test]["ref_return"]).abs().max() < 1e-3


TEST_LENGTH_PAPER = REPO_ROOT / "research" / "study" / "test_length_paper" / "margins.csv"


@pytest.mark.skipif(not (TEST_LENGTH_PAPER.is_file() and (BUNDLE / "evals.csv").is_file()),
                    reason="no committed re-test of the published paper-HGM networks")
def test_the_paper_hgm_re_tests_table_is_its_csv_and_its_short_test_is_the_published_one():
    """Section 15: the published paper-HGM networks of scenario 3 re-tested on 160 episodes. The re-test's
    first 48 episodes are the published test, so they must give docs/results' numbers for both hosts."""
    study = pd.read_csv(TEST_LENGTH_PAPER)
    text = _study_section("15")


    tables = {test: part.set_index("seed") for test, part in study[study["model"] == "proposed"].groupby("test")}
    for seed in tables["preset"].index:
        cells = [_margin_cell(tables[test].loc[seed]) for test in ("preset", "long")]
        assert f"| {seed} | " + " | ".join(cells) + " |" in text, seed
    evals = _evals()
    s3 = evals[evals["scenario"] == "3"].set_index(["model", "seed"])
    for seed, row in tables["preset"].iterrows():
        assert abs(row["episode_return"] - s3.loc[("proposed", seed), "episode_return"]) < 1e-3
        assert abs(row["collisions"] - s3.loc[("proposed", seed), "collisions"]) < 1e-6
        assert abs(row["ref_return"] - s3.loc[("human", seed), "episode_return"]) < 1e-3
