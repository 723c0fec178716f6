"""Results bundles: what `load_store` read comes back from the files unchanged, dtypes included."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import tables
from analysis.__main__ import main
from analysis.bundle import (
    FORMAT_VERSION,
    MANIFEST,
    TABLE_FILES,
    BundleError,
    load_bundle,
    portable_uri,
    write_bundle,
)
from analysis.load import StoreData, load_store
from analysis.synthetic import SyntheticSpec, synthetic_frames, write_store


def assert_same_data(a: StoreData, b: StoreData) -> None:
    assert (portable_uri(a.tracking_uri), a.experiment, a.dropped, a.configs) == (
        portable_uri(b.tracking_uri), b.experiment, b.dropped, b.configs)
    for name in TABLE_FILES:
        pd.testing.assert_frame_equal(getattr(a, name), getattr(b, name), check_exact=True, obj=name)
    assert (a.git_commits, a.git_dirty) == (b.git_commits, b.git_dirty)


def awkward_data() -> StoreData:
    """Values a naive CSV round trip changes: int-looking text, seeds that are not ints, NaN, "" scenarios."""
    evals, curves, episodes = synthetic_frames(SyntheticSpec(seeds=(0, 1), models=("proposed", "human"),
                                                             episodes=2))
    evals.loc[0, "collisions"] = np.nan
    evals.loc[1, "avg_speed_kmh"] = 0.1 + 0.2  # not the shortest decimal: exactness shows
    runs = pd.DataFrame({
        "run_id": ["t0", "e0", "e1", "e2"],
        "status": ["FINISHED", "FINISHED", "RUNNING", "FINISHED"],
        "start_time": [1, 2, 3, 4],
        "parent_run_id": [None, "p", "p", None],
        "stage": ["train", "eval", "eval", "eval"],
        "model": ["proposed", "proposed", "human", "human"],
        "scenario": pd.array(["train", "01", "", "5"], dtype="string"),
        "seed": [0, "s7", 1, 2],  # one seed tag that is not a number keeps the column mixed, as load_store does
        "train_key": ["tk", "tk", None, "tk"],
        "params.learner.lr": ["2.50e-4", "2.50e-4", None, "007"],
        "metrics.eval/episode_return": [np.nan, 1.5, -2.25, 1e300],
    })
    return StoreData(tracking_uri="sqlite:////somewhere/mlflow.db", experiment="exp", runs=runs, curves=curves,
                     evals=evals, episodes=episodes,
                     configs={"proposed": "learner:\n  lr: 2.5e-4  # café\n", "human": "model: {name: human}\n"},
                     dropped=["1 FAILED/KILLED run(s) left out"])


def test_round_trip_keeps_every_value_and_dtype(tmp_path: Path) -> None:
    data = awkward_data()
    files = write_bundle(data, tmp_path / "b")
    assert {p.name for p in files} == {*(f for f, _ in TABLE_FILES.values()), "proposed.yaml", "human.yaml",
                                       MANIFEST}
    back = load_bundle(tmp_path / "b")
    assert_same_data(data, back)
    assert back.runs["seed"].tolist() == [0, "s7", 1, 2]
    lr = back.runs["params.learner.lr"]
    assert lr.isna().tolist() == [False, False, True, False] and lr[3] == "007"
    assert back.evals["seed"].dtype == np.int64 and back.evals["scenario"].map(type).eq(str).all()


def test_round_trip_of_empty_tables(tmp_path: Path) -> None:
    # Only non-learning hosts evaluated: no training curves, and no episodes table logged.
    data = awkward_data()
    data.curves = pd.DataFrame(columns=["run_id", "model", "seed", "train_key", "metric", "step", "value"])
    data.episodes = pd.DataFrame(columns=["run_id", "model", "scenario", "seed", "episode"])
    write_bundle(data, tmp_path)
    assert_same_data(data, load_bundle(tmp_path))


def test_rewriting_a_bundle_leaves_no_stale_config(tmp_path: Path) -> None:
    data = awkward_data()
    write_bundle(data, tmp_path)
    data.configs = {"proposed": data.configs["proposed"]}
    write_bundle(data, tmp_path)
    assert not (tmp_path / "configs" / "human.yaml").exists()
    assert load_bundle(tmp_path).configs == data.configs


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> str:
    spec = SyntheticSpec(seeds=(0, 1), models=("proposed", "min", "human"), episodes=2)
    return write_store(tmp_path_factory.mktemp("store"), spec)


def test_bundle_of_a_real_store_equals_what_load_store_read(store: str, tmp_path: Path) -> None:
    assert main(["--tracking-uri", store, "--write-bundle", str(tmp_path), "--no-report"]) == 0
    data, back = load_store(store), load_bundle(tmp_path)
    assert_same_data(data, back)
    assert back.runs["scenario"].dtype == "string" and back.runs["seed"].dtype == np.int64
    pd.testing.assert_frame_equal(tables.summary(data.evals), tables.summary(back.evals), check_exact=True)
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    assert manifest["tracking_uri"] == portable_uri(store) and manifest["git_commits"] == ["abc1234"]
    assert manifest["tables"]["evals"]["rows"] == 3 * 5 * 2


def test_bundle_of_another_format_version_names_both(tmp_path: Path) -> None:
    write_bundle(awkward_data(), tmp_path)
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    manifest["format_version"] = FORMAT_VERSION + 1
    (tmp_path / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(BundleError, match=f"format version {FORMAT_VERSION + 1}.*format version {FORMAT_VERSION}"):
        load_bundle(tmp_path)


@pytest.mark.parametrize("make", ["missing", "empty"])
def test_no_bundle_gets_one_clear_message(tmp_path: Path, make: str, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "results"
    if make == "empty":
        target.mkdir()
    assert main(["--bundle", str(target), "--no-pictures"]) == 1
    err = capsys.readouterr().err
    assert f"no results bundle at {target}" in err
    assert ("does not exist" if make == "missing" else "is empty") in err


def test_help_documents_the_bundle(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for flag in ("--bundle", "--write-bundle", "--no-report"):
        assert flag in text
    for name, _ in TABLE_FILES.values():
        assert name in text
    assert "configs/<model>.yaml" in text and MANIFEST in text


def test_no_report_needs_a_bundle_to_write() -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--no-report"])
    assert exit_.value.code == 2


@pytest.mark.parametrize("damage", ["truncate", "garble"])
def test_damaged_bundle_gets_one_line_naming_the_file(tmp_path: Path, damage: str,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    write_bundle(awkward_data(), tmp_path)
    evals = tmp_path / "evals.csv"
    text = evals.read_text()
    if damage == "truncate":  # cut in the middle of a row, as an interrupted copy leaves it
        evals.write_text(text[: len(text) // 2 + 3])
    else:
        evals.write_text(text.replace(",0,", ",zero,", 1))
    assert main(["--bundle", str(tmp_path), "--no-pictures"]) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and str(evals) in lines[0] and "Traceback" not in err, err


def test_the_manifest_holds_no_path_of_the_machine_that_wrote_it(tmp_path: Path) -> None:
    data = awkward_data()
    data.tracking_uri = f"sqlite:///{tmp_path / 'deep' / 'mlflow.db'}; sqlite:///{tmp_path / 'variant.db'}"
    write_bundle(data, tmp_path / "bundle")
    text = (tmp_path / "bundle" / MANIFEST).read_text()
    assert str(tmp_path) not in text
    assert json.loads(text)["tracking_uri"] == "sqlite:///mlflow.db; sqlite:///variant.db"
    assert portable_uri("http://tracking.example:5000") == "http://tracking.example:5000"
    assert portable_uri("/abs/dir/mlruns") == "mlruns"
