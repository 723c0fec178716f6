"""The whole chain on real runs: a smoke sweep writes the store, `python -m analysis` reads it,
and the report built from a bundle of that store equals the one built from the store."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from mlflow import MlflowClient
from pypdf import PdfReader

from analysis.__main__ import main as analysis_main
from analysis.bundle import TABLE_FILES
from analysis.figures import image_variance
from analysis.labels import fmt
from analysis.report import SECTION_TITLES
from tests.helpers import pdf_text
from tests.helpers.cli import hgm


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cwd = tmp_path_factory.mktemp("sweep")
    hgm(cwd, "-m", "experiment=smoke", "model=proposed,human", "scenario=1,5", "tracking.log_gif=false")
    return cwd


@pytest.fixture(scope="module")
def store_report(swept: Path) -> Path:
    out = swept / "reports"
    assert analysis_main(["--tracking-uri", f"sqlite:///{swept / 'mlflow.db'}", "--out", str(out)]) == 0
    return out


def test_report_from_a_real_smoke_sweep(swept: Path, store_report: Path) -> None:
    uri = f"sqlite:///{swept / 'mlflow.db'}"
    out = store_report
    text = pdf_text(out / "report.pdf")
    for title in SECTION_TITLES:
        assert title in text, title
    # Every evaluation mean in the store appears, formatted, in the report's tables.
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name("hgm_repro")
    evals = client.search_runs([exp.experiment_id], "tags.stage = 'eval'")
    assert len(evals) == 4
    for run in evals:
        for metric in ("episode_return", "avg_speed_kmh"):
            value = run.data.metrics[f"eval/{metric}"]
            assert fmt(value, metric) in text, (run.data.tags["model"], run.data.tags["scenario"], metric)
    for name in ("fig5_speed", "fig_test_results"):
        assert image_variance(out / f"{name}.png") > 0
    assert "1 seed" in text  # one seed: the report says there is no interval instead of inventing one
    # Page 1 answers: a smoke run says it is not a result; what each host earns and how often it crashes,
    # every claim with its verdict, and the scale beside the paper's in one line, without markup.
    first = " ".join((PdfReader(str(out / "report.pdf")).pages[0].extract_text() or "").split())
    for needed in ("SMOKE RUN: NOT A RESULT", "What each host earns and how often it crashes",
                   "Episode return, scenario 3", "Collisions, mean of scenarios", "Human", "Scale of these runs",
                   "smoke (Proposed): 256 training steps per seed (paper 1,000,000); images 36x36, 2 "
                   "frames (paper 84x84, 4)", "checkpoint (paper: the final network)",
                   "test episodes per cell (paper: about 834)", "Student-t", "coverage", "inconclusive"):
        assert needed in first, (needed, first)
    assert "`" not in first
    for number in range(1, 8):
        assert f"{number}. " in first
    assert "Smoke run: not a result" in (out / "results.md").read_text()
    # results.md: Table 6 beside the paper's numbers, the side metrics, each claim with its verdict.
    markdown = (out / "results.md").read_text()
    for needed in ("(paper 1927)", "(paper 1969)", "| Human |", "## Collisions per episode", "- smoke (Proposed",
                   "![Fig. 5: training speed](fig5_speed.png)"):
        assert needed in markdown, needed
    assert markdown.split("\n## ")[1].startswith("What each host earns")  # results.md opens with the headline
    claim_rows = [line for line in markdown.splitlines() if line.startswith("| ") and "**" in line]
    assert [row.split(" | ")[0] for row in claim_rows] == [f"| {n}" for n in range(1, 8)]
    assert "**inconclusive**" in markdown  # one seed cannot decide a claim


def test_report_from_a_bundle_of_the_real_sweep(swept: Path, store_report: Path) -> None:
    bundle, out = swept / "bundle", swept / "reports_from_bundle"
    uri = f"sqlite:///{swept / 'mlflow.db'}"
    assert analysis_main(["--tracking-uri", uri, "--write-bundle", str(bundle), "--no-report"]) == 0
    assert not out.exists()
    (swept / "mlflow.db").rename(swept / "moved.db")  # the bundle alone must do
    try:
        assert analysis_main(["--bundle", str(bundle), "--out", str(out)]) == 0
    finally:
        (swept / "moved.db").rename(swept / "mlflow.db")
    assert {p.name for p in bundle.iterdir()} >= {name for name, _ in TABLE_FILES.values()}
    assert (out / "report.pdf").stat().st_size > 50_000
    # Table 6 with its CIs, the claims and every word of the report are those the store gave.
    for table in ("test_summary.csv", "claims.csv", "results.md"):
        assert (out / table).read_text() == (store_report / table).read_text(), table
    assert "episode_return" in (out / "test_summary.csv").read_text()

    def undated(text: str) -> str:
        text = re.sub(r"Generated \d{4}-\d\d-\d\d \d\d:\d\d", "Generated", text)
        return re.sub(r"Data .*? Experiment ", "Data Experiment ", text)  # the store's path, or the bundle's name

    bundle_text = pdf_text(out / "report.pdf")
    assert undated(bundle_text) == undated(pdf_text(store_report / "report.pdf"))
    # Built from a bundle, the report names the bundle, never the machine the store was on.
    assert "Data results bundle bundle/" in bundle_text
    assert str(swept) not in bundle_text and "sqlite:" not in bundle_text
    assert image_variance(out / "fig5_speed.png") > 0
