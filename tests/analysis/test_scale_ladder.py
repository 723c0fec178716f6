"""The evals' `experiment` column (store, bundle, older bundles) and the report's scale-ladder page: two rungs run,
one not, each rung judged on its own runs beside the shared human-driven host."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd
import pytest
from matplotlib.collections import LineCollection

from analysis import ladder, ladder_figure
from analysis.bundle import MANIFEST, load_bundle, write_bundle
from analysis.claims import SUPPORTED, evaluate_claims
from analysis.figures import image_variance
from analysis.labels import LEARNED, fmt
from analysis.load import StoreData, load_store
from analysis.pipeline import build_outputs
from analysis.report import fmt_estimate
from analysis.rung import absence
from analysis.scenarios import with_cv_ratio
from analysis.stats import COVERAGE_SEEDS, mean_ci
from analysis.synthetic import SyntheticSpec, synthetic_frames, write_store
from tests.helpers import pdf_text

SEEDS = (0, 1, 2, 3, 4)  # COVERAGE_SEEDS: the tables show intervals


def frames(experiment: str, models: tuple[str, ...], **effects: dict[str, float]) -> tuple[pd.DataFrame, ...]:
    spec = SyntheticSpec(seeds=SEEDS, models=models, episodes=2, experiment=experiment, rng_seed=len(experiment))
    for name, values in effects.items():
        setattr(spec, name, {**getattr(spec, name), **values})
    return synthetic_frames(spec)


def runs_of(evals: pd.DataFrame, curves: pd.DataFrame) -> pd.DataFrame:
    """Evaluation runs naming their preset as the app logs it; training runs name none."""
    train = curves.drop_duplicates("run_id")[["run_id", "model", "seed", "train_key"]].assign(stage="train")
    tested = evals[["run_id", "model", "scenario", "seed", "train_key"]].assign(
        stage="eval", **{"params.experiment.name": evals["experiment"]})
    return pd.concat([train, tested], ignore_index=True).assign(status="FINISHED", git_commit="abc1234")


def two_rungs() -> StoreData:
    """The quick rung (the paper's three methods, the human-driven host and a variant) and the paper's-steps
    rung, at which Coordinate scores above proposed: claim 7 turns from supported to not supported."""
    parts = [frames("quick", (*LEARNED, "human")), frames("quick160", ("proposed_enriched",)),
             frames("paper_steps", LEARNED, return_base={"coordinate": 2000.0})]
    # (The variant has no training curves: an empty frame in the concat would turn the steps into objects.)
    evals, curves, episodes = (pd.concat([p[i] for p in parts if not p[i].empty], ignore_index=True)
                               for i in range(3))
    return StoreData(tracking_uri="sqlite:////ladder/mlflow.db", experiment="hgm_repro", runs=runs_of(evals, curves),
                     curves=curves, evals=evals.drop(columns="experiment"), episodes=episodes)


def test_every_eval_row_names_its_preset_and_a_bundle_keeps_it(tmp_path: Path) -> None:
    data = two_rungs()  # built without the column: it is derived from the runs' experiment.name
    assert list(data.evals.columns[:5]) == ["run_id", "model", "scenario", "seed", "experiment"]
    by_model = data.evals.groupby("model")["experiment"].agg(lambda s: sorted(set(s)))
    assert by_model.to_dict() == {"proposed": ["paper_steps", "quick"], "min": ["paper_steps", "quick"],
                                  "coordinate": ["paper_steps", "quick"], "human": ["quick"],
                                  "proposed_enriched": ["quick160"]}
    write_bundle(data, tmp_path / "bundle")
    assert "experiment" in pd.read_csv(tmp_path / "bundle" / "evals.csv").columns
    again = load_bundle(tmp_path / "bundle")
    pd.testing.assert_frame_equal(again.evals, data.evals, check_exact=True)


def test_an_older_bundle_gets_the_column_from_its_runs(tmp_path: Path) -> None:
    data = two_rungs()
    runs = data.runs.copy()
    first = runs.index[runs["model"].eq("human") & runs["stage"].eq("eval")]
    runs.loc[first[0], "params.experiment.name"] = None
    runs["preset"] = None
    runs.loc[first[0], "preset"] = "quick_by_tag"  # no param: the preset tag says it
    runs.loc[first[1], "params.experiment.name"] = None  # neither
    write_bundle(StoreData(tracking_uri=data.tracking_uri, experiment=data.experiment, runs=runs,
                           curves=data.curves, evals=data.evals, episodes=data.episodes), tmp_path / "old")
    # The bundle as written before evals.csv had the column.
    evals_csv = tmp_path / "old" / "evals.csv"
    pd.read_csv(evals_csv, dtype=str, keep_default_na=False).drop(columns="experiment").to_csv(evals_csv, index=False)
    manifest = json.loads((tmp_path / "old" / MANIFEST).read_text())
    del manifest["tables"]["evals"]["columns"]["experiment"]
    (tmp_path / "old" / MANIFEST).write_text(json.dumps(manifest))
    old = load_bundle(tmp_path / "old").evals.set_index("run_id")["experiment"]
    expected = data.evals.set_index("run_id")["experiment"].copy()
    expected[runs.loc[first[0], "run_id"]] = "quick_by_tag"
    expected[runs.loc[first[1], "run_id"]] = "unknown"
    pd.testing.assert_series_equal(old, expected)


def test_a_store_keeps_each_presets_runs_of_one_model(tmp_path: Path) -> None:
    small = {"seeds": (0, 1), "scenarios": ("3",), "episodes": 2}
    uri = write_store(tmp_path, SyntheticSpec(models=("proposed", "human"), experiment="quick", **small))
    write_store(tmp_path, SyntheticSpec(models=("proposed",), experiment="paper_steps", **small), with_parent=False)
    data = load_store(uri)
    counts = data.evals.groupby(["model", "experiment"]).size().to_dict()
    assert counts == {("proposed", "quick"): 2, ("proposed", "paper_steps"): 2, ("human", "quick"): 2}
    assert not data.dropped  # two presets of one cell are not duplicates
    assert set(data.curves["train_key"]) == {"tk-proposed-quick", "tk-proposed-paper_steps"}


def cell(evals: pd.DataFrame, model: str, experiment: str, metric: str) -> str:
    """The scenario-3 mean over seeds, with its t interval from the seed count whose coverage is measured only."""
    rows = evals[(evals["model"] == model) & (evals["experiment"] == experiment) & (evals["scenario"] == "3")]
    e = mean_ci(rows.groupby("seed")[metric].mean().to_numpy(float))
    return fmt_estimate(e.point, e.low, e.high, e.n, metric) if e.n >= COVERAGE_SEEDS else fmt(e.point, metric)


def test_each_rung_is_judged_on_its_own_runs_and_a_missing_one_reads_not_run() -> None:
    data = two_rungs()
    evals = with_cv_ratio(data.evals, data.runs)
    section, numbers, verdicts, _, _ = ladder.section(evals, data.curves, data.episodes)
    tables = [b.rows for b in section.blocks if b.rows is not None]
    paras = [b.text for b in section.blocks if b.rows is None]
    quick, steps, _shifts, claims = tables
    assert [row[0] for row in quick[1:]] == ["Proposed", "Min", "Coordinate", "Human (every rung)"]
    for table, experiment in ((quick, "quick"), (steps, "paper_steps")):
        for row, model in zip(table[1:4], LEARNED, strict=True):
            assert row[1:4] == [str(len(SEEDS)), cell(evals, model, experiment, "episode_return"),
                                cell(evals, model, experiment, "collisions")]
            # How it drives: the mean over seeds of each seed's scenario-3 speed and lane changes.
            mine = evals[(evals["model"] == model) & (evals["experiment"] == experiment) & (evals["scenario"] == "3")]
            per_seed = mine.groupby("seed")[["avg_speed_kmh", "lane_changes"]].mean().mean()
            assert row[4] == f"{fmt(per_seed['avg_speed_kmh'], digits=1)}, {fmt(per_seed['lane_changes'], digits=2)}"
        # The human-driven host's runs stand beside every rung, and every seed is paired with them.
        assert table[4][2] == cell(evals, "human", "quick", "episode_return")
        assert table[1][5].startswith(f"{len(SEEDS)} of {len(SEEDS)}")
    assert "Variant" not in str(tables) and "enriched" not in "".join(r[0] for t in tables for r in t)
    assert any(p.startswith("Rung 3, paper_pixels: the paper's pixels (160k steps, 84x84x4): not run.")
               for p in paras)
    assert any(p.startswith("Rung 2, paper_steps: the paper's steps (1M steps, Table 4's learner, 36x36x2). "
                            "Trainings: Proposed: seeds 0, 1, 2, 3 and 4 tested.") for p in paras)
    # Each rung's verdicts are evaluate_claims on that rung's runs alone.
    for name in ("quick", "paper_steps"):
        rung = ladder.rung(evals, data.curves, data.episodes, name)
        assert set(rung.evals["experiment"]) == {name, "quick"}  # the human-driven host's runs are the quick ones
        assert list(verdicts[name]) == [c.verdict for c in evaluate_claims(rung.evals, rung.curves)]
    assert verdicts.loc[6, "quick"] == SUPPORTED and verdicts.loc[6, "paper_steps"] == "not supported"
    assert list(verdicts["paper_pixels"]) == ["not run"] * 7
    assert claims[0] == ["Claim", "quick", "paper_steps", "paper_pixels"] and claims[7][1:] == [
        "supported", "not supported", "not run"]
    assert set(numbers["rung"]) == set(ladder.RUNGS) and not numbers.loc[numbers["rung"] == "paper_pixels",
                                                                         "ran"].any()


def test_a_rung_or_method_with_nothing_tested_reads_under_way_only_where_its_training_started() -> None:
    going = {("paper_steps", "coordinate"), ("paper_pixels", "min")}
    assert absence("paper_steps", going, "coordinate") == "under way"
    assert absence("paper_steps", going, "min") == "not run"  # another method's training on the rung is not its own
    assert absence("paper_pixels", going, "coordinate") == "not run"  # nor its training on another rung
    assert absence("paper_steps", going) == "under way"  # the rung as a whole: any method's training
    assert absence("quick", going) == "not run" and absence("paper_steps", set(), "coordinate") == "not run"


def test_the_other_pages_read_one_preset_per_model(tmp_path: Path) -> None:
    data = two_rungs()
    main = ladder.main_view(data)
    assert set(zip(main.evals["model"], main.evals["experiment"], strict=True)) == {
        (m, "quick") for m in (*LEARNED, "human")} | {("proposed_enriched", "quick160")}
    assert set(main.curves["train_key"]) == {f"tk-{m}-quick" for m in LEARNED}  # not the paper_steps trainings
    assert set(main.episodes["run_id"]) == set(main.evals["run_id"])
    assert any("paper_steps (25 evaluation runs) are read by the scale-ladder page only" in n for n in main.dropped)


def test_page_one_says_what_the_rungs_above_found_with_their_seed_counts() -> None:
    data = two_rungs()
    evals = with_cv_ratio(data.evals, data.runs)
    numbers = ladder.section(evals, data.curves, data.episodes)[1]
    lines = ladder.page_one_lines(numbers, {"quick", "quick160"}, len(SEEDS))
    steps = "; ".join(f"{name} {cell(evals, model, 'paper_steps', 'episode_return')} return, "
                      f"{cell(evals, model, 'paper_steps', 'collisions')} collisions (5 seeds; "
                      f"{beats} beat the human-driven host)"
                      for name, model, beats in (("Proposed", "proposed", 5), ("Min", "min", 5),
                                                 ("Coordinate", "coordinate", 5)))
    assert lines == [f"The paper's steps (1M steps, Table 4's learner, 36x36x2), scenario 3, per episode "
                     f"(scale ladder): {steps}.",
                     "The paper's pixels (160k steps, 84x84x4): not run yet (scale ladder)."]
    # One seed of one method: its numbers stand alone, said once to have no interval.
    one = evals[(evals["experiment"] != "paper_steps") | ((evals["model"] == "proposed") & (evals["seed"] == 0))]
    numbers = ladder.section(one, data.curves, data.episodes)[1]
    row = numbers[(numbers["rung"] == "paper_steps") & (numbers["model"] == "proposed")].iloc[0]
    first = ladder.page_one_lines(numbers, {"quick", "quick160"}, len(SEEDS))[0]
    assert (f"Proposed {fmt(row['episode_return/point'], 'episode_return')} return, "
            f"{fmt(row['collisions/point'], 'collisions')} collisions (1 of 5 seeds, no CI; 1 beat") in first
    assert first.endswith("; Min and Coordinate not run.") and "[" not in first
    # A method whose training was stopped part-way, none of its seeds tested, is under way, not "not run".
    going = ladder.page_one_lines(numbers, {"quick", "quick160"}, len(SEEDS), {("paper_steps", "min")})[0]
    assert going.endswith("; Min under way, no seed tested yet; Coordinate not run.")
    # Three seeds of each (enough for a claim's verdict, short of the count whose coverage is measured): the
    # means alone, each said to have no interval.
    three = evals[(evals["experiment"] != "paper_steps") | (evals["seed"] < 3)]
    numbers = ladder.section(three, data.curves, data.episodes)[1]
    line = ladder.page_one_lines(numbers, {"quick", "quick160"}, len(SEEDS))[0]
    assert "[" not in line and line.count("(3 of 5 seeds, no CI; ") == len(LEARNED)
    assert f"Min {cell(three, 'min', 'paper_steps', 'episode_return')} return" in line
    # A seed whose human-driven host has no test: the count beating it says how many seeds were paired.
    unpaired = evals[(evals["model"] != "human") | (evals["seed"] != 4)]
    numbers = ladder.section(unpaired, data.curves, data.episodes)[1]
    line = ladder.page_one_lines(numbers, {"quick", "quick160"}, len(SEEDS))[0]
    assert line.count("(5 seeds; 4 of 4 beat the human-driven host)") == len(LEARNED)
    # Nothing above the shown presets has run: page 1 says nothing of the ladder.
    quick_only = evals[evals["experiment"] != "paper_steps"]
    assert ladder.page_one_lines(ladder.section(quick_only, data.curves, data.episodes)[1], {"quick", "quick160"},
                                 len(SEEDS)) == []


@pytest.fixture(scope="module")
def ladder_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("ladder")
    write_bundle(two_rungs(), root / "bundle")
    build_outputs(load_bundle(root / "bundle"), root / "report", pictures=False)
    return root / "report"


def test_the_report_and_results_md_carry_the_ladder(ladder_report: Path) -> None:
    text = " ".join(pdf_text(ladder_report / "report.pdf").split())
    markdown = (ladder_report / "results.md").read_text()
    assert f"## {ladder.TITLE}" in markdown and ladder.TITLE in text
    for where in (text, markdown):
        assert "Rung 3, paper_pixels: the paper's pixels (160k steps, 84x84x4): not run." in where
        # Page 1 (and results.md's scale) says what the rung above the main pages' found.
        assert ("The paper's steps (1M steps, Table 4's learner, 36x36x2), scenario 3, per episode (scale ladder): "
                "Proposed") in where
        assert "Rung 2, paper_steps: the paper's steps (1M steps, Table 4's learner, 36x36x2)." in where
    assert text.index("The paper's steps (1M steps, Table 4's learner, 36x36x2), scenario 3") < text.index(
        "page 2")
    assert "| 7. Coordinate scores below proposed: the HGM is what helps. | supported | not supported | not run |" \
        in markdown
    numbers = pd.read_csv(ladder_report / "scale_ladder.csv")
    assert numbers.groupby("rung")["ran"].first().to_dict() == {"paper_pixels": False, "paper_steps": True,
                                                                "quick": True}
    # The main pages' claims read the quick runs only: claim 7 holds there as on the quick rung.
    assert pd.read_csv(ladder_report / "claims.csv")["verdict"].iloc[6] == SUPPORTED


def test_the_ladder_figure_draws_each_rungs_seeds_and_the_tables_means() -> None:
    data = two_rungs()
    evals = with_cv_ratio(data.evals, data.runs)
    # At the paper's steps, one seed of Min and four of Coordinate: below COVERAGE_SEEDS, seeds and a mean with
    # no interval (as in the tables; four seeds are enough for a claim's verdict, yet their interval's coverage is
    # not measured), beside proposed's five.
    steps = evals["experiment"] == "paper_steps"
    evals = evals[~steps | ((evals["model"] != "min") | (evals["seed"] == 1))
                  & ((evals["model"] != "coordinate") | (evals["seed"] < 4))]
    rungs = ladder.rungs(evals, data.curves, data.episodes)
    section, numbers = ladder.section(evals, data.curves, data.episodes)[:2]
    # The steps rung's table prints the same: Min's and Coordinate's means alone, proposed's with its interval.
    steps_table = [b.rows for b in section.blocks if b.rows is not None][1]
    for row, model in zip(steps_table[1:4], LEARNED, strict=True):
        assert row[2:4] == [cell(evals, model, "paper_steps", m) for m in ("episode_return", "collisions")]
        assert ("[" in row[2]) == (model == "proposed"), row
    fig = ladder_figure.draw(rungs, numbers, ladder.REFERENCE)
    try:
        for ax, metric in zip(fig.axes, ladder_figure.METRICS, strict=True):
            marks = {a.get_gid(): a for a in ax.get_children() if a.get_gid()}
            drawn = set()
            for _, row in numbers[numbers["model"].isin(LEARNED)].iterrows():
                name = f"{row['rung']}/{row['model']}"
                if not row["seeds"]:
                    assert f"mean/{name}" not in marks  # a method not run draws nothing, not a zero
                    continue
                drawn.add(name)
                assert marks[f"mean/{name}"].get_ydata()[0] == pytest.approx(row[f"{metric}/point"])
                mine = evals[(evals["model"] == row["model"]) & (evals["experiment"] == row["rung"])
                             & (evals["scenario"] == "3")]
                seeds = mine.groupby("seed")[metric].mean().to_numpy(float)
                assert sorted(marks[f"seeds/{name}"].get_offsets()[:, 1]) == pytest.approx(sorted(seeds))
                assert (f"interval/{name}" in marks) == (len(seeds) >= COVERAGE_SEEDS), name
                if len(seeds) >= COVERAGE_SEEDS:  # the bar spans the table's interval
                    (bar,) = [a for a in ax.get_children()
                              if a.get_gid() == f"interval/{name}" and isinstance(a, LineCollection)]
                    (segment,) = bar.get_segments()
                    assert sorted(segment[:, 1]) == pytest.approx([row[f"{metric}/low"], row[f"{metric}/high"]])
            assert drawn == {f"{e}/{m}" for e in ("quick", "paper_steps") for m in LEARNED}
            human = numbers[numbers["model"] == ladder.REFERENCE].iloc[0]
            assert marks[f"reference/{ladder.REFERENCE}"].get_ydata()[0] == pytest.approx(human[f"{metric}/point"])
            assert [t.get_text() for t in ax.texts].count("not run") == len(LEARNED)  # the paper's pixels
            counts = [t.get_text() for t in ax.texts]
            assert "n=1" in counts and "n=4" in counts  # Min and Coordinate at the paper's steps
    finally:
        plt.close(fig)
    # A training stopped part-way on a rung where its method has no seed tested yet reads "under way", not
    # "not run"; the other methods there still read "not run".
    fig = ladder_figure.draw(rungs, numbers, ladder.REFERENCE, under_way={("paper_pixels", "coordinate")})
    try:
        for ax in fig.axes:
            marks = [t.get_text() for t in ax.texts]
            assert marks.count("under way") == 1 and marks.count("not run") == len(LEARNED) - 1
    finally:
        plt.close(fig)
    # No learned host's run on any rung: no figure.
    human_only = evals[evals["model"] == ladder.REFERENCE]
    assert ladder_figure.figure(ladder.rungs(human_only, data.curves, data.episodes), numbers, ladder.REFERENCE,
                                Path("/nonexistent/fig")) is None


def test_the_report_leads_the_ladder_with_its_figure(ladder_report: Path) -> None:
    png = ladder_report / f"{ladder.FIGURE}.png"
    assert png.exists() and image_variance(png) > 0
    markdown = (ladder_report / "results.md").read_text()
    ladder_part = markdown[markdown.index(f"## {ladder.TITLE}"):]
    assert ladder_part.index(f"]({ladder.FIGURE}.png)") < ladder_part.index("Rung 1, quick")
    assert f"its 95 % t interval (from {COVERAGE_SEEDS} seeds" in ladder_part  # as the figure draws it


def test_training_hours_sum_the_logged_intervals_and_stops_come_from_the_resumes_tag() -> None:
    # 2,000 steps at 100 steps/s, then 2,000 at 50 (a resumed session on a busier machine): 20 s + 40 s.
    curves = pd.DataFrame({"train_key": ["a", "a", "b", "a"], "metric": ["steps_per_s", "steps_per_s", "steps_per_s",
                                                                       "loss"],
                           "step": [2000, 4000, 3600, 4000], "value": [100.0, 50.0, 1.0, 9.0]})
    runs = pd.DataFrame({"train_key": ["a", "b", "a"], "stage": ["train", "train", "eval"],
                         "resumes": ["2", None, None]})
    costs = ladder.training_costs(curves, runs).set_index("train_key")
    assert costs.loc["a", "hours"] == pytest.approx(60 / 3600) and costs.loc["b", "hours"] == pytest.approx(1.0)
    assert (costs.loc["a", "stops"], costs.loc["b", "stops"]) == (2, 0)
    assert ladder.training_costs(curves[curves["metric"] == "loss"]).empty


def test_a_higher_rung_is_read_against_the_quick_one_seed_by_seed() -> None:
    data = two_rungs()
    evals = with_cv_ratio(data.evals, data.runs)
    # The steps rung's proposed host lacks seed 2: it pairs only the seeds both rungs tested.
    gone = (evals["model"] == "proposed") & (evals["experiment"] == "paper_steps") & (evals["seed"] == 2)
    evals = evals[~gone]
    section, _, _, _, shifts = ladder.section(evals, data.curves, data.episodes)
    assert set(shifts["rung"]) == {"paper_steps"}  # the quick rung is the base; the pixels rung did not run
    assert set(shifts["model"]) == set(LEARNED)
    assert set(shifts["metric"]) == set(ladder.SHIFT_METRICS)

    def scenario3(model: str, experiment: str, metric: str) -> pd.Series:
        rows = evals[(evals["model"] == model) & (evals["experiment"] == experiment) & (evals["scenario"] == "3")]
        return rows.groupby("seed")[metric].mean()

    for _, row in shifts.iterrows():
        high = scenario3(row["model"], "paper_steps", row["metric"])
        low = scenario3(row["model"], "quick", row["metric"])
        differences = (high - low.reindex(high.index)).to_numpy()
        expected = mean_ci(differences)
        assert row["n"] == (4 if row["model"] == "proposed" else 5) == len(differences)
        assert row["point"] == pytest.approx(expected.point)
        assert (row["low"], row["high"]) == pytest.approx((expected.low, expected.high))
    coordinate = shifts[(shifts["model"] == "coordinate") & (shifts["metric"] == "episode_return")].iloc[0]
    assert coordinate["low"] > 0  # the steps rung's Coordinate scores far above its quick twin (two_rungs)
    rows = [b.rows for b in section.blocks if b.rows and b.rows[0][0] == "Rung, method"]
    assert len(rows) == 1 and [r[0] for r in rows[0][1:]] == ["paper_steps, Proposed", "paper_steps, Min",
                                                              "paper_steps, Coordinate"]
    assert rows[0][1][1] == "4"
    assert rows[0][3][2] == fmt_estimate(coordinate["point"], coordinate["low"], coordinate["high"], 5,
                                         "episode_return")
    # Four seeds paired: each shift's mean alone, as its interval's coverage is measured at five.
    proposed = shifts[shifts["model"] == "proposed"].set_index("metric")
    assert rows[0][1][2:] == [fmt(proposed.loc[m, "point"], m) for m in ladder.SHIFT_METRICS]
