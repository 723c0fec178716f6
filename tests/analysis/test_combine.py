"""Several results read as one (`analysis.combine`, `--bundle A B`): a variant beside the published grid."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from analysis import tables
from analysis.__main__ import main
from analysis.bundle import load_bundle, write_bundle
from analysis.combine import combine
from analysis.load import StoreData
from analysis.synthetic import SyntheticSpec, synthetic_frames


def data_of(models: tuple[str, ...], source: str, rng_seed: int = 7) -> StoreData:
    evals, curves, episodes = synthetic_frames(SyntheticSpec(seeds=(0, 1, 2), models=models, episodes=2,
                                                             rng_seed=rng_seed))
    runs = evals[["run_id", "model", "scenario", "seed"]].assign(stage="eval", status="FINISHED",
                                                                 git_commit=source)
    return StoreData(tracking_uri=f"sqlite:////{source}/mlflow.db", experiment="hgm_repro", runs=runs,
                     curves=curves, evals=evals, episodes=episodes,
                     configs={m: f"model: {{name: {m}}}  # {source}\n" for m in models}, source=source)


def test_distinct_models_are_all_kept() -> None:
    grid, variant = data_of(("proposed", "min", "human"), "grid"), data_of(("proposed_enriched",), "variant")
    both = combine([grid, variant])
    for name in ("runs", "curves", "evals", "episodes"):
        assert len(getattr(both, name)) == len(getattr(grid, name)) + len(getattr(variant, name)), name
    assert set(both.configs) == {"proposed", "min", "human", "proposed_enriched"}
    assert both.dropped == [] and both.source == "grid + variant"
    assert both.tracking_uri == "sqlite:////grid/mlflow.db; sqlite:////variant/mlflow.db"
    # Combined again with one of its own sources: no source is named twice.
    assert combine([both, variant]).tracking_uri == both.tracking_uri
    assert both.git_commits == ["grid", "variant"]
    # The test table reads the variant as one more method, its cells unchanged by the company it keeps.
    summary = tables.summary(both.evals)
    alone = tables.summary(variant.evals)
    pd.testing.assert_frame_equal(summary[summary["model"] == "proposed_enriched"].reset_index(drop=True),
                                  alone.reset_index(drop=True))


def test_a_later_source_replaces_a_model_whole_and_says_so() -> None:
    grid = data_of(("proposed", "min", "human"), "grid")
    rerun = data_of(("proposed",), "rerun", rng_seed=11)
    both = combine([grid, rerun])
    mine = both.evals[both.evals["model"] == "proposed"]
    pd.testing.assert_frame_equal(mine.reset_index(drop=True), rerun.evals.reset_index(drop=True))
    assert len(both.evals) == len(grid.evals)  # replaced, not doubled
    assert set(both.runs[both.runs["model"] == "proposed"]["git_commit"]) == {"rerun"}
    assert set(both.curves[both.curves["model"] == "proposed"]["run_id"]) == set(rerun.curves["run_id"])
    assert both.configs["proposed"] == rerun.configs["proposed"] and "# grid" in both.configs["min"]
    assert both.dropped == ["model proposed (synthetic) of grid replaced by a later source's runs of it"]


def test_the_same_model_at_another_preset_is_kept_beside_it() -> None:
    # A rung of the scale ladder (paper_steps) published beside the quick grid: nothing is replaced.
    grid = data_of(("proposed", "human"), "grid")
    rung = data_of(("proposed",), "rung", rng_seed=11)
    rung.runs = rung.runs.assign(**{"params.experiment.name": "paper_steps"})
    rung.evals = rung.evals.assign(experiment="paper_steps")
    grid.evals = grid.evals.assign(experiment="quick")
    grid.runs = grid.runs.assign(**{"params.experiment.name": "quick"})
    grid.configs = {m: f"experiment: {{name: quick}}  # grid {m}\n" for m in grid.configs}
    rung.configs = {"proposed": "experiment: {name: paper_steps}  # rung\n"}
    both = combine([grid, rung])
    assert both.dropped == []
    # The report describes the grid by its models' configs: the rung's does not replace the grid's.
    assert "# grid proposed" in both.configs["proposed"]
    for name in ("runs", "curves", "evals", "episodes"):
        assert len(getattr(both, name)) == len(getattr(grid, name)) + len(getattr(rung, name)), name
    assert both.evals.groupby("experiment")["model"].apply(set).to_dict() == {
        "quick": {"proposed", "human"}, "paper_steps": {"proposed"}}
    # The rung published again replaces only itself, and says at which preset.
    again = combine([both, rung])
    assert len(again.evals) == len(both.evals)
    assert again.dropped == ["model proposed (paper_steps) of grid + rung replaced by a later source's runs of it"]


def test_one_source_is_itself() -> None:
    grid = data_of(("proposed", "human"), "grid")
    assert combine([grid]) is grid
    with pytest.raises(ValueError, match="at least one"):
        combine([])


def test_cli_reads_several_bundles_as_one_and_writes_them_back_as_one(tmp_path: Path) -> None:
    grid, variant = data_of(("proposed", "min", "human"), "grid"), data_of(("proposed_enriched",), "variant")
    write_bundle(grid, tmp_path / "grid")
    write_bundle(variant, tmp_path / "variant")
    # Into the grid's own folder, as research/studies/publish_variant.sh does: it reads before it writes.
    assert main(["--bundle", str(tmp_path / "grid"), str(tmp_path / "variant"), "--write-bundle",
                 str(tmp_path / "grid"), "--no-report"]) == 0
    back = load_bundle(tmp_path / "grid")
    assert sorted(back.evals["model"].unique()) == ["human", "min", "proposed", "proposed_enriched"]
    assert len(back.evals) == len(grid.evals) + len(variant.evals)
    # Run again (a variant published twice): its runs replace themselves, nothing doubles.
    assert main(["--bundle", str(tmp_path / "grid"), str(tmp_path / "variant"), "--write-bundle",
                 str(tmp_path / "grid"), "--no-report"]) == 0
    again = load_bundle(tmp_path / "grid")
    assert len(again.evals) == len(back.evals)
    assert sum("proposed_enriched" in note for note in again.dropped) == 1
    assert main(["--bundle", str(tmp_path / "grid"), str(tmp_path / "variant"), "--write-bundle",
                 str(tmp_path / "grid"), "--no-report"]) == 0
    assert load_bundle(tmp_path / "grid").dropped == again.dropped  # the note does not pile up
