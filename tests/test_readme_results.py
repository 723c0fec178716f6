"""The README's Results section tells the committed results bundle (docs/results) to the printed digit: its
table of return and collisions per host, the paired differences to the human-driven host it quotes, and the
verdict on each of the paper's claims, so that a re-published bundle cannot leave the README behind."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from analysis.claims import NOT_SUPPORTED, SUPPORTED, TIE, VERDICTS
from analysis.labels import fmt
from analysis.load import at_main_experiments
from analysis.stats import difference_ci
from analysis.tables import headline, per_scenario
from tests.helpers import REPO_ROOT

README = REPO_ROOT / "README.md"
BUNDLE = REPO_ROOT / "docs" / "results"
SCENARIOS = ["1", "2", "3", "4", "5"]
# The README table's row labels and the models they stand for.
ROWS = {"Proposed (HGM + camera)": "proposed", "Min (camera)": "min", "Coordinate (V2X vector + camera)": "coordinate",
        "Variant: enriched HGM, 160k steps": "proposed_enriched",
        "Guarded proposed (not the paper's)": "proposed_guarded", "Guarded Min (not the paper's)": "min_guarded",
        "Guarded Coordinate (not the paper's)": "coordinate_guarded",
        "Human-driven host": "human",
        "IDM + MOBIL": "idm_mobil"}
# The table's columns after the label, as headline() names them.
COLUMNS = ["episode_return/scenario", "episode_return/mean", "collisions/scenario", "collisions/mean"]
# The sentences that quote a host's paired return difference to the human-driven host, and the model each quotes.
PAIRED = {"the proposed host's": "proposed", "its": "proposed_enriched",
          "the guarded proposed host's": "proposed_guarded"}
CELL = re.compile(r"^([+-]?\d+(?:\.\d+)?) \[([+-]?\d+(?:\.\d+)?), ([+-]?\d+(?:\.\d+)?)\]$")
needs_bundle = pytest.mark.skipif(not (BUNDLE / "evals.csv").is_file(), reason="no committed results bundle")


def _results_section() -> str:
    text = README.read_text()
    assert "\n## Results\n" in text, "the README has no Results section"
    return text.split("\n## Results\n", 1)[1].split("\n## ", 1)[0]


def _evals() -> pd.DataFrame:
    # The grid's rows: a rung of the scale ladder publishes its runs of the same models beside them.
    return at_main_experiments(pd.read_csv(BUNDLE / "evals.csv", dtype={"scenario": str}))


def _same_to_the_printed_digit(shown: str, exact: float) -> bool:
    """`shown` is `exact` written, as the report writes numbers (`fmt`), with as many decimals as `shown` has (a
    sign and -0 aside)."""
    decimals = len(shown.split(".", 1)[1]) if "." in shown else 0
    return float(shown) == float(fmt(exact, digits=decimals))


def _table(section: str) -> dict[str, list[str]]:
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] in ROWS:
            rows[cells[0]] = cells[1:]
    return rows


def _mismatches(section: str, evals: pd.DataFrame) -> list[str]:
    """Every cell of the README's Results table that differs from the bundle's headline numbers."""
    table = headline(evals, SCENARIOS).set_index("model")
    rows = _table(section)
    wrong = [f"rows {sorted(rows)} are not {sorted(ROWS)}"] if set(rows) != set(ROWS) else []
    for label, cells in rows.items():
        if len(cells) != len(COLUMNS):
            wrong.append(f"{label}: {len(cells)} cells")
            continue
        for column, cell in zip(COLUMNS, cells, strict=True):
            parsed = CELL.match(cell)
            want = [table.loc[ROWS[label], f"{column}/{part}"] for part in ("point", "low", "high")]
            if not parsed or not all(map(_same_to_the_printed_digit, parsed.groups(), want)):
                wrong.append(f"{label}, {column}: {cell!r}, the bundle {want}")
    return wrong


@needs_bundle
def test_the_readmes_results_table_is_the_bundles_to_the_printed_digit():
    assert _mismatches(_results_section(), _evals()) == []


@needs_bundle
def test_the_check_fails_when_one_readme_number_changes():
    section, evals = _results_section(), _evals()
    row = next(line for line in section.splitlines() if line.startswith("| Proposed (HGM + camera) |"))
    cells = row.split("|")
    cells[2] = re.sub(r"\d+", lambda m: str(int(m.group()) + 1), cells[2], count=1)  # the scenario-3 return + 1
    assert _mismatches(section.replace(row, "|".join(cells)), evals)


def _verdict(low: float, high: float) -> str:
    return SUPPORTED if low > 0 else NOT_SUPPORTED if high < 0 else TIE


@needs_bundle
@pytest.mark.parametrize("whose", sorted(PAIRED))
def test_the_paired_differences_to_the_human_driven_host_are_the_bundles(whose: str):
    text = " ".join(_results_section().split())
    number = r"([+-]?\d+) \[(-?\d+), (-?\d+)\]"
    quoted = re.search(rf"{whose} return minus the human-driven host's is {number} per episode in scenario 3 and "
                       rf"{number} over the mean of scenarios: a \*\*({'|'.join(VERDICTS)})\*\*", text)
    assert quoted, f"the README's sentence on {whose} return minus the human-driven host's is gone"
    evals = _evals()
    mine, human = per_scenario(evals, PAIRED[whose], "episode_return"), per_scenario(evals, "human", "episode_return")
    estimates = [difference_ci({"3": mine["3"]}, {"3": human["3"]}), difference_ci(mine, human)]
    for shown, est in zip((quoted.groups()[:3], quoted.groups()[3:6]), estimates, strict=True):
        assert all(map(_same_to_the_printed_digit, shown, (est.point, est.low, est.high))), (shown, est)
    # The word is the report's: a tie where either interval covers 0.
    words = {_verdict(est.low, est.high) for est in estimates}
    assert quoted.group(7) == (TIE if TIE in words else words.pop())


@pytest.mark.skipif(not (BUNDLE / "report" / "claims.csv").is_file(), reason="no committed claims table")
def test_the_readme_gives_each_claim_the_reports_verdict():
    text = " ".join(_results_section().split())
    sentence = text.split("The paper's seven claims on these seeds:", 1)
    assert len(sentence) == 2, "the README's sentence on the paper's claims is gone"
    said = {}
    for word, numbers in re.findall(rf"\*\*({'|'.join(VERDICTS)})\*\*: claims? ((?:\d+(?:, | and )?)+)", sentence[1]):
        said |= {int(n): word for n in re.findall(r"\d+", numbers)}
    claims = pd.read_csv(BUNDLE / "report" / "claims.csv")
    assert said == dict(zip(claims["claim"].astype(int), claims["verdict"], strict=True))


# The README's scale-ladder table: each row's label begins with its method and rung (the human-driven host: the
# quick rung's).
LADDER_ROWS = {"proposed, quick": ("quick", "proposed"), "proposed, the paper's steps": ("paper_steps", "proposed"),
               "proposed, the paper's pixels": ("paper_pixels", "proposed"), "Min, quick": ("quick", "min"),
               "Min, the paper's steps": ("paper_steps", "min"), "Min, the paper's pixels": ("paper_pixels", "min"),
               "Coordinate, quick": ("quick", "coordinate"),
               "Coordinate, the paper's steps": ("paper_steps", "coordinate"),
               "Coordinate, the paper's pixels": ("paper_pixels", "coordinate"),
               "human-driven host": ("quick", "human")}
LADDER_CELL = re.compile(r"^([+-]?\d+(?:\.\d+)?)(?: \[([+-]?\d+(?:\.\d+)?), ([+-]?\d+(?:\.\d+)?)\])?$")


def _ladder_mismatches(section: str, ladder: pd.DataFrame) -> list[str]:
    """Every cell of the README's scale-ladder table that differs from the report's scale_ladder.csv."""
    table = ladder.set_index(["rung", "model"])
    wrong, seen = [], set()
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        row = next((r for prefix, r in LADDER_ROWS.items() if line.startswith("|") and cells[0].startswith(prefix)),
                   None)
        if row is None:
            continue
        seen.add(row)
        for cell, column in zip(cells[1:3], ("episode_return", "collisions"), strict=True):
            parsed = LADDER_CELL.match(cell)
            want = [table.loc[row, f"{column}/{part}"] for part in ("point", "low", "high")]
            shown = [g for g in parsed.groups() if g is not None] if parsed else []
            if not shown or not all(map(_same_to_the_printed_digit, shown, want)):
                wrong.append(f"{cells[0]}, {column}: {cell!r}, the report {want}")
        hours = table.loc[row, "training_hours"]  # none for a host that does not train: "-"
        if pd.isna(hours):
            hours_right = cells[3] == "-"
        else:
            hours_right = cells[3] != "-" and _same_to_the_printed_digit(cells[3], hours)
        if not hours_right:
            wrong.append(f"{cells[0]}, CPU-hours: {cells[3]!r}, the report {hours}")
        driving = [table.loc[row, metric] for metric in ("avg_speed_kmh", "lane_changes")]
        shown = cells[4].split(", ") if len(cells) > 4 else []
        if len(shown) != 2 or not all(map(_same_to_the_printed_digit, shown, driving)):
            wrong.append(f"{cells[0]}, speed and lane changes: {cells[4] if len(cells) > 4 else None!r}, "
                         f"the report {driving}")
    missing = set(LADDER_ROWS.values()) - seen
    return wrong + ([f"rows {sorted(missing)} are not in the table"] if missing else [])


@pytest.mark.skipif(not (BUNDLE / "report" / "scale_ladder.csv").is_file(), reason="no committed scale ladder")
def test_the_readmes_scale_ladder_is_the_reports():
    section = _results_section()
    ladder = pd.read_csv(BUNDLE / "report" / "scale_ladder.csv")
    assert _ladder_mismatches(section, ladder) == []
    # The check can fail: one number of the table changed is caught, in either kind of column.
    for said, wrong in (("| 224 [213, 235] | 0 |", "| 225 [213, 235] | 0 |"), ("| 51.0, 2.98 |", "| 51.0, 2.99 |")):
        changed = section.replace(said, wrong, 1)
        assert changed != section and _ladder_mismatches(changed, ladder) != []
