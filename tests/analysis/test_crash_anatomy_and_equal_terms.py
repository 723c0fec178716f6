"""The report's crash anatomy (from the episodes' event columns) and its "On equal terms" section (the claims
judged on the guarded forms), from hand-built tables and through a store, a bundle and the report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import crashes, equal_terms
from analysis.bundle import load_bundle, write_bundle
from analysis.claims import evaluate_claims
from analysis.labels import GUARDED, fmt, model_label
from analysis.load import load_store
from analysis.pipeline import build_outputs
from analysis.synthetic import SyntheticSpec, synthetic_frames, write_store
from hgm_repro.contracts import events
from tests.helpers import pdf_text

NO_EVENT = {events.LANE_CHANGE_AGE: 240.0, events.LANE_CHANGE_REQUESTS: 0.0, events.REFUSED_BY_GAP: 0.0,
            events.REFUSED_BY_PARITY: 0.0, events.CRASH_INTO_LEADER: 0.0, events.CRASH_FROM_BEHIND: 0.0,
            events.CRASH_PARTNER_CHANGING: 0.0, events.CRASH_HOST_CHANGING: 0.0}


def episode(model: str, scenario: str, collisions: float = 0.0, lane_changes: float = 0.0, **recorded: float) -> dict:
    return {"model": model, "scenario": scenario, "seed": 0, "collisions": collisions, "lane_changes": lane_changes,
            **NO_EVENT, **recorded}


def hand_built() -> pd.DataFrame:
    return pd.DataFrame([
        # proposed, scenario 3: one crash of each kind but 'other', and one safe episode.
        episode("proposed", "3", 1, 1, lane_change_age=4, crash_into_leader=1, crash_host_changing=1,
                lane_change_requests=1),
        episode("proposed", "3", 1, 0, crash_into_leader=1),
        episode("proposed", "3", 1, 0, crash_from_behind=1),
        episode("proposed", "3", 0, 0),
        # proposed, scenario 1: a car cutting in.
        episode("proposed", "1", 1, 0, crash_into_leader=1, crash_partner_changing=1),
        # the human-driven host never crashes; the layer refused it 3 of 8 requests, 1 by the parity alone.
        episode("human", "3", 0, 5, lane_change_requests=8, lane_changes_refused_gap=2, lane_changes_refused_parity=1),
    ])


def test_anatomy_counts_each_kind_per_host_and_scenario(tmp_path: Path):
    table = crashes.anatomy(hand_built()).set_index(["model", "scenario"])
    three = table.loc[("proposed", "3")]
    assert (three["episodes"], three["crashes"]) == (4, 3)
    assert [three[k] for k in events.CRASH_KINDS] == [1, 1, 1, 0]
    assert three["lane_change_share"] == pytest.approx(1 / 3)
    assert table.loc[("proposed", "1"), "other"] == 1
    human = table.loc[("human", "3")]
    assert (human["crashes"], human["refused_gap_share"], human["refused_parity_share"]) == (0, 0.25, 0.125)
    # The PDF and Markdown rows: hosts that crashed, each kind's count with its share of the crashes.
    rows = crashes.anatomy_rows(crashes.anatomy(hand_built()))
    assert rows[1][:5] == ["Proposed", "1", "1", "1.000", "0"] and rows[2][4:] == ["1 (33%)"] * 3 + ["0"]
    assert crashes.refusal_rows(crashes.anatomy(hand_built()))[1][2:] == ["25%", "12%"]
    section, _, figure = crashes.section(hand_built(), tmp_path)
    assert figure is not None and (tmp_path / "crash_anatomy.csv").is_file()
    assert any("Human-driven host" in b.text for b in section.blocks)  # named as never crashing


def test_tests_without_the_event_columns_say_the_anatomy_is_not_recorded(tmp_path: Path):
    _, _, old = synthetic_frames(SyntheticSpec(seeds=(0,), models=("proposed",), episodes=2))
    section, table, figure = crashes.section(old, tmp_path)
    assert table.empty and figure is None
    assert [b.text for b in section.blocks] == [crashes.NOT_RECORDED]
    # A bundle combined from old and new tests: only the rows that recorded the events count.
    mixed = pd.concat([old.assign(scenario="1"), hand_built()], ignore_index=True)
    assert crashes.anatomy(mixed)["episodes"].sum() == len(hand_built())
    said = " ".join(b.text for b in crashes.section(mixed, tmp_path)[0].blocks if isinstance(b.text, str))
    assert f"Not recorded for {model_label('proposed')} (in {len(old)} of the {len(mixed)} test episodes)" in said


GRID = ("proposed", "min", "coordinate", "human", "idm_mobil", *GUARDED)


def guarded_spec(**kw) -> SyntheticSpec:
    # The guarded forms in reverse order of the paper's methods: claim 5 flips on them.
    spec = SyntheticSpec(seeds=(0, 1, 2), models=GRID, episodes=2, **kw)
    spec.return_base.update(proposed_guarded=1750.0, min_guarded=1850.0, coordinate_guarded=1800.0,
                            idm_mobil=1900.0)
    for guarded, method in GUARDED.items():
        for table in (spec.return_slope, spec.speed, spec.lane_changes, spec.overtakes, spec.tau,
                      spec.overtake_wiggle):
            table.setdefault(guarded, table[method])
    return spec


def test_the_claims_on_equal_terms_read_the_guarded_forms_in_place_of_the_methods():
    evals, curves, _ = synthetic_frames(guarded_spec())
    assert equal_terms.section(evals[~evals["model"].isin(list(GUARDED))], curves, []) is None  # none: no section
    renamed = evals[evals["model"].isin([*GUARDED, "human", "idm_mobil"])].replace({"model": GUARDED})
    renamed_curves = curves[curves["model"].isin(list(GUARDED))].replace({"model": GUARDED})
    expected = evaluate_claims(renamed, renamed_curves)
    got = equal_terms.guarded_claims(evals, curves)
    assert [(c.number, c.verdict) for c in got] == [(c.number, c.verdict) for c in expected]
    paper = {c.number: c.verdict for c in evaluate_claims(evals, curves)}
    assert paper[5] == "supported" and {c.number: c.verdict for c in got}[5] == "not supported"


def test_the_mark_sentence_states_the_guarded_return_against_idm_mobil():
    evals, _, _ = synthetic_frames(guarded_spec())
    three = evals[evals["scenario"] == "3"].groupby("model")["episode_return"].mean()
    text = equal_terms.mark_sentence(evals)
    assert f"earns {fmt(three['proposed_guarded'], digits=1)} per episode" in text
    assert f"against {fmt(three['idm_mobil'], digits=1)} for IDM + MOBIL" in text
    share = (three["proposed_guarded"] - three["human"]) / (three["idm_mobil"] - three["human"])
    assert f"covers {share:.0%} of the way" in text
    no_mark = evals[evals["model"] != "idm_mobil"]
    assert "IDM + MOBIL, the mark under the same layer, has no test" in equal_terms.mark_sentence(no_mark)


def test_the_seeds_sentence_counts_safe_wins_over_the_same_seeds_human_driven_host():
    rows = [dict(model=m, scenario="3", seed=seed, episode_return=r, collisions=c)
            for m, seed, r, c in [("human", 0, 200.0, 0.0), ("human", 1, 300.0, 0.0), ("human", 2, 250.0, 0.0),
                                  ("proposed_guarded", 0, 210.0, 0.0),    # wins, safe
                                  ("proposed_guarded", 1, 290.0, 0.0),    # loses
                                  ("proposed_guarded", 2, 260.0, 0.06)]]  # wins, but not under 0.05
    text = equal_terms.seeds_sentence(pd.DataFrame(rows))
    assert text is not None and "on 1 of 3 seeds" in text and "under 0.05 collisions" in text
    assert equal_terms.seeds_sentence(pd.DataFrame(rows[:3])) is None


@pytest.fixture(scope="module")
def guarded_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store with the paper's grid, the guarded grid and the reference hosts; its episodes given event
    records; through a bundle to the report."""
    root = tmp_path_factory.mktemp("guarded")
    data = load_store(write_store(root / "store", guarded_spec()), "hgm_repro")
    rng = np.random.default_rng(0)
    n = len(data.episodes)
    crashed = rng.random(n) < 0.5
    data.episodes = data.episodes.assign(
        collisions=crashed.astype(float), lane_changes=rng.integers(0, 3, n).astype(float),
        **{**NO_EVENT, events.LANE_CHANGE_AGE: rng.integers(0, 20, n).astype(float),
           events.CRASH_INTO_LEADER: (crashed & (rng.random(n) < 0.5)).astype(float)})
    data.episodes.loc[data.episodes["model"].isin(["human", "idm_mobil"]), "collisions"] = 0.0
    write_bundle(data, root / "bundle")
    out = root / "report"
    build_outputs(load_bundle(root / "bundle"), out, pictures=False)
    return out


def test_the_report_and_results_md_carry_both_sections(guarded_report: Path):
    text = pdf_text(guarded_report / "report.pdf")
    markdown = (guarded_report / "results.md").read_text()
    for where in (text, markdown):
        assert equal_terms.TITLE in where and crashes.TITLE in where
        assert "Guarded: proposed under the safety layer (not the paper's)" in where or "Proposed (guarded)" in where
    assert "| Claim | Statement | Paper's methods | Guarded forms |" in markdown
    assert "fig_crash_anatomy.png" in markdown and (guarded_report / "fig_crash_anatomy.png").is_file()
    table = pd.read_csv(guarded_report / "crash_anatomy.csv")
    assert set(table["model"]) == set(GRID) and (table.loc[table["model"] == "human", "crashes"] == 0).all()


def test_each_crashed_host_gets_its_kinds_pooled_and_the_spread_over_its_seeds():
    frame = hand_built()
    # A second seed of the proposed host whose one crash is a rear-end: its lane-change share is 0.
    frame = pd.concat([frame, pd.DataFrame([{**episode("proposed", "3", 1, 0, crash_into_leader=1), "seed": 1}])],
                      ignore_index=True)
    said = crashes.host_sentences(crashes.anatomy(frame), frame)
    assert said == ["Proposed: 5 crashes in 6 test episodes (0.833 per episode): 1 in a lane change (20%), "
                    "2 rear-ends (40%), 1 hit from behind (20%), 1 other (20%). By seed, lane changes are 0% (seed 1) "
                    "to 25% (seed 0) of its crashes."]
    shares = crashes.seed_shares(frame).set_index(["model", "seed"])
    assert shares.loc[("proposed", 1), "rear_end_share"] == 1.0 and shares.loc[("proposed", 0), "crashes"] == 4


def test_a_hosts_crash_free_scenarios_count_in_its_pooled_rate():
    frame = hand_built()
    # Two more episodes of the proposed host in scenario 5, neither of which crashed.
    frame = pd.concat([frame, pd.DataFrame([episode("proposed", "5", 0, i) for i in (0, 1)])], ignore_index=True)
    (said,) = crashes.host_sentences(crashes.anatomy(frame), frame)
    assert said.startswith("Proposed: 4 crashes in 7 test episodes (0.571 per episode)")
