"""The benchmark's output format (its numbers are for people, not for asserts)."""

from __future__ import annotations

import json

import pytest
import torch

from hgm_repro.bench import main

REQUIRED = {"what", "device", "n_envs", "camera", "env_steps_per_s"}


def test_bench_prints_one_json_object_per_configuration(capsys):
    assert main(["--only", "simulator", "--only", "observations", "--n-envs", "2", "--obs-n-envs", "2",
                 "--seconds", "0.05", "--device", "cpu"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.strip()]
    rows = [json.loads(line) for line in lines]  # every stdout line is JSON
    assert len(rows) == 1 + 8 + 1  # the simulator, each observation variant, the proposed one under resets
    for row in rows:
        assert REQUIRED <= set(row)
        assert row["env_steps_per_s"] > 0
    assert {r["what"] for r in rows} >= {"simulator", "simulator+proposed", "simulator+hgm"}


def test_bench_learner_reports_updates_per_second(capsys):
    assert main(["--only", "learner", "--seconds", "0.05", "--train-steps", "128", "--device", "cpu"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    update = next(r for r in rows if r["what"] == "learner update")
    assert update["updates_per_s"] > 0 and update["batch_size"] == 64
    assert any(r["what"].startswith("learner training") and r["env_steps_per_s"] > 0 for r in rows)


def test_bench_measures_the_torchrl_env_and_the_gymnasium_vector_env_side_by_side(capsys):
    assert main(["--only", "envs", "--env-n-envs", "3", "--seconds", "0.05", "--device", "cpu"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert [r["what"] for r in rows] == ["torchrl env", "gymnasium vector env"]
    for row in rows:
        assert REQUIRED <= set(row) and row["n_envs"] == 3 and row["env_steps_per_s"] > 0
        assert (row["camera"], row["hgm"], row["image"]) == ("front", "paper", "84x84")
    assert rows[1]["vs_torchrl_env"] == round(rows[1]["env_steps_per_s"] / rows[0]["env_steps_per_s"], 3)


@pytest.mark.slow  # five short trainings: about a minute on a busy CPU
def test_bench_grouped_training_lines_for_members_grouped_solo_and_parallel(capfd):
    assert main(["--only", "grouped", "--train-steps", "128", "--members", "2", "--device", "cpu"]) == 0
    # capfd, not capsys: the parallel path's worker processes write to the same stdout, and every
    # line there must be JSON too (their TorchRL logging once was not).
    rows = [json.loads(line) for line in capfd.readouterr().out.splitlines() if line.strip()]
    assert [(r["members"], r["path"], r["torch_threads"] == 1) for r in rows][:1] == \
        [(1, "solo, one after another", True)]
    parallel = {(2, "solo, 2 jobs at once")} if torch.get_num_threads() > 1 else set()
    assert {(r["members"], r["path"]) for r in rows[1:]} == {(2, "grouped"), (2, "solo, one after another")} | parallel
    for row in rows:
        assert REQUIRED <= set(row) and row["env_steps_per_s"] > 0 and row["updates_per_s"] > 0
    assert all("vs_one_member_one_thread" in r for r in rows[1:])


def test_grouped_training_members_are_valid_jobs_of_the_current_preset():
    # The members train without validation; the preset they start from must still accept that
    # (the quick preset tests best.pt, which needs validation unless the member says otherwise).
    from hgm_repro.bench import _member_job

    job = _member_job(torch.device("cpu"), total_steps=64, seed=3, threads=1)
    assert job.eval.val_every == 0 and job.eval.checkpoint == "final" and job.seed == 3


def test_bench_protocol_lines_rate_and_grouped_update(capsys):
    # What scripts/gpu/protocol.sh asks for: named variants at several sizes, the rate line the
    # training budget is sized from, and one grouped update per mode (a failing mode gives its error).
    assert main(["--only", "observations", "--variants", "proposed", "--obs-n-envs", "2,3", "--only", "rate",
                 "--only", "grouped_update", "--preset", "smoke", "--rate-members", "2", "--rate-steps", "32",
                 "--update-members", "2", "--update-modes", "eager,bf16", "--seconds", "0.05", "--device", "cpu"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert [(r["what"], r["n_envs"]) for r in rows[:2]] == [("simulator+proposed", 2), ("simulator+proposed", 3)]
    rate = rows[2]
    assert rate["what"] == "learner training, members (smoke preset, end to end)" and rate["members"] == 2
    assert rate["member_env_steps_per_s"] > 0 and rate["fixed_s"] >= 0 and rate["member_steps"] == 32
    eager, bf16 = rows[3:]
    assert (eager["what"], eager["mode"], eager["members"]) == ("grouped update", "eager", 2)
    assert eager["updates_per_s"] > 0 and eager["member_updates_per_s"] == pytest.approx(2 * eager["updates_per_s"],
                                                                                          abs=0.2)  # both rounded
    assert bf16["mode"] == "bf16" and "needs a CUDA device" in bf16["error"]
