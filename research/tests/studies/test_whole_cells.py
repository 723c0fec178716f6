"""research/studies/whole_cells.py: a copy of a study store cut to what is whole, the source untouched."""

from __future__ import annotations

import pytest

from research.tests.studies import load_study


def _module():
    return load_study("whole_cells")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A store mid-study: a whole model, a model 2 cells in, a safest model with one seed refused part-way,
    and a training still running."""
    from mlflow import MlflowClient

    path = tmp_path_factory.mktemp("store") / "mlflow.db"
    client = MlflowClient(tracking_uri=f"sqlite:///{path}")
    experiment = client.create_experiment("hgm_repro")

    def run(stage, model, seed, scenario="", status="FINISHED"):
        tags = {"stage": stage, "model": model, "seed": str(seed), "scenario": scenario,
                "train_key": f"{model.removesuffix('_safest')}{seed}"}
        created = client.create_run(experiment, tags=tags)
        client.set_terminated(created.info.run_id, status)

    for seed in range(2):
        run("train", "whole", seed)
        run("train", "part", seed, status="FINISHED" if seed == 0 else "KILLED")
        for scenario in "12":
            run("eval", "whole", seed, scenario)
    run("eval", "part", 0, "1")
    run("train", "other", 9, status="RUNNING")  # trained by nobody's kept test yet
    for scenario in "12":
        run("eval", "whole_safest", 0, scenario)
    run("eval", "whole_safest", 1, "1")
    return path


def test_the_copy_keeps_what_is_whole_and_the_store_is_untouched(store, tmp_path, capsys):
    module = _module()
    before = store.read_bytes()
    copy = tmp_path / "whole" / "mlflow.db"
    assert module.main([str(store), str(copy), "--cells", "4", "--scenarios", "2"]) == 0
    said = capsys.readouterr().out
    assert "part: 1 of 4 cells, dropped with its trainings" in said and "whole: 4 cells, kept" in said
    assert "whole_safest: seeds kept ['0'], dropped ['1']" in said
    assert store.read_bytes() == before

    from mlflow import MlflowClient

    client = MlflowClient(tracking_uri=f"sqlite:///{copy}")
    experiment = client.get_experiment_by_name("hgm_repro").experiment_id
    kept = [(r.data.tags["stage"], r.data.tags["model"], r.data.tags["seed"], r.data.tags["scenario"])
            for r in client.search_runs([experiment])]
    assert sorted(kept) == sorted([*[("eval", "whole", str(s), c) for s in range(2) for c in "12"],
                                   ("train", "whole", "0", ""), ("train", "whole", "1", ""),
                                   ("eval", "whole_safest", "0", "1"), ("eval", "whole_safest", "0", "2")])
    # A dry run prints the same and drops nothing.
    dry = tmp_path / "dry.db"
    assert module.main([str(store), str(dry), "--cells", "4", "--scenarios", "2", "--dry-run"]) == 0
    assert "(dry run)" in capsys.readouterr().out
    assert len(MlflowClient(tracking_uri=f"sqlite:///{dry}").search_runs([experiment])) == 13


def test_bad_input_is_named_before_any_copy(tmp_path, capsys):
    module = _module()
    assert module.main([str(tmp_path / "none.db"), str(tmp_path / "copy.db")]) == 2
    assert "no store at" in capsys.readouterr().err and not (tmp_path / "copy.db").exists()
