"""The whole chain on real runs: a smoke sweep writes the store, `python -m analysis` reads it."""

from __future__ import annotations

from pathlib import Path

import pytest
from mlflow import MlflowClient
from pypdf import PdfReader

from analysis.__main__ import main as analysis_main
from analysis.figures import image_variance
from analysis.labels import fmt
from analysis.report import SECTION_TITLES

from .test_sweep import hgm


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cwd = tmp_path_factory.mktemp("sweep")
    hgm(cwd, "-m", "experiment=smoke", "model=proposed,human", "scenario=1,5", "tracking.log_gif=false")
    return cwd


def test_report_from_a_real_smoke_sweep(swept: Path) -> None:
    uri = f"sqlite:///{swept / 'mlflow.db'}"
    out = swept / "reports"
    assert analysis_main(["--tracking-uri", uri, "--out", str(out)]) == 0
    reader = PdfReader(str(out / "report.pdf"))
    text = " ".join(" ".join(page.extract_text() or "" for page in reader.pages).split())
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
