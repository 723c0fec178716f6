"""Training at the CPU's limit: the overlapped loop (a second thread collects while the network
learns) and bf16 autocast of the update on CPU; what `auto` picks, and the refusals."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import torch

from hgm_repro.contracts import runtime_choice
from hgm_repro.contracts.checkpoint import load_checkpoint
from hgm_repro.contracts.errors import ConfigError
from hgm_repro.contracts.names import TRAINING_RATES
from hgm_repro.learner import train
from tests.helpers.learner import Recorder, compose_job

OVERLAPPED = ("runtime.overlap=true",)
needs_bf16 = pytest.mark.skipif(not runtime_choice.cpu_has_bf16(), reason="this CPU has no native bf16")


def _digest(path: Path) -> str:
    network = load_checkpoint(path)["network"]
    return hashlib.sha256(b"".join(t.numpy().tobytes() for t in network.values())).hexdigest()[:16]


def _values(log: Recorder) -> list[tuple[int, dict[str, float]]]:
    return [(step, {k: v for k, v in metrics.items() if k.removeprefix("train/") not in TRAINING_RATES})
            for step, metrics in log.calls]


def _losses(log: Recorder) -> list[float]:
    return [round(m["train/loss"], 6) for _, m in log.calls if "train/loss" in m]


@pytest.fixture(scope="module")
def overlapped_run(tmp_path_factory) -> tuple[Path, Recorder]:
    log = Recorder()
    return train(compose_job("seed=3", *OVERLAPPED), tmp_path_factory.mktemp("overlapped"), log), log


def test_the_overlapped_loop_gives_the_same_training_twice(overlapped_run, tmp_path: Path):
    final, log = overlapped_run
    again = Recorder()
    assert _digest(train(compose_job("seed=3", *OVERLAPPED), tmp_path, again)) == _digest(final)
    assert _values(again) == _values(log)  # every logged value but the speed, validation included, to the bit
    state = load_checkpoint(final)
    assert state["finished"] and state["env_steps"] == 128 and state["updates"] == (128 - 32) // 4 + 1


def test_the_overlapped_loop_acts_one_batch_behind(overlapped_run, tmp_path: Path):
    # Same traffic, same first weights, same updates per batch: only the acting weights lag one
    # batch, so the greedy actions (and with them the losses) part ways once learning has begun.
    final, log = overlapped_run
    solo = Recorder()
    baseline = train(compose_job("seed=3"), tmp_path, solo)
    assert load_checkpoint(baseline)["updates"] == load_checkpoint(final)["updates"]
    assert _losses(solo) != _losses(log)


def test_two_torch_threads_give_the_same_training_twice(tmp_path: Path):
    # The default path on a 2-core CPU: the collect-then-update loop with torch's threads on both cores.
    runs = []
    for name in ("first", "second"):
        log = Recorder()
        runs.append((_digest(train(compose_job("seed=4", "runtime.torch_threads=2"), tmp_path / name, log)),
                     _values(log)))
    assert runs[0] == runs[1]


def test_an_overlapped_run_killed_mid_training_resumes_and_stops_at_the_same_step(tmp_path: Path):
    job = compose_job(*OVERLAPPED)
    with pytest.raises(KeyboardInterrupt):
        train(job, tmp_path, Recorder(stop_at=96))  # killed after the step-64 checkpoint, a batch in flight
    last = load_checkpoint(tmp_path / "last.pt", job)
    assert last["env_steps"] == 64 and not last["finished"]
    log = Recorder()
    state = load_checkpoint(train(job, tmp_path, log), job)
    assert state["env_steps"] == 128 and state["finished"] and state["updates"] > last["updates"]
    assert log.steps("train/epsilon") == [96, 128]


@needs_bf16
def test_bf16_updates_on_cpu_train_with_float32_weights(tmp_path: Path):
    job = compose_job("runtime.update_dtype=bfloat16")
    assert runtime_choice.update_dtype(job.runtime.update_dtype, job.device) == torch.bfloat16
    log = Recorder()
    state = load_checkpoint(train(job, tmp_path, log), job)
    assert all(t.dtype == torch.float32 for t in state["network"].values())
    losses = _losses(log)
    assert losses and all(torch.isfinite(torch.tensor(losses)))
    # The forward passes did run in bf16: the float32 run of the same job learns other weights.
    float32 = load_checkpoint(train(compose_job(), tmp_path / "f32", Recorder()))
    pairs = zip(state["network"].values(), float32["network"].values(), strict=True)
    assert any(not torch.equal(a, b) for a, b in pairs)


def test_bf16_is_refused_in_one_line_on_a_cpu_without_it(monkeypatch):
    monkeypatch.setattr(runtime_choice, "cpu_has_bf16", lambda: False)
    with pytest.raises(ConfigError, match=r"runtime.update_dtype=bfloat16 is not allowed here: this CPU has neither"):
        compose_job("runtime.update_dtype=bfloat16")
    # auto never asks for it on a CPU, supported or not.
    assert runtime_choice.update_dtype("auto", "cpu") == torch.float32


def test_an_unknown_setting_is_refused_with_what_is_allowed():
    with pytest.raises(ConfigError, match="runtime.overlap"):
        compose_job("runtime.overlap=sometimes")
    with pytest.raises(ConfigError, match="runtime.update_dtype"):
        compose_job("runtime.update_dtype=float16")


@pytest.mark.parametrize(("cores", "omp", "expected"), [(2, None, True), (2, "1", False), (1, None, False),
                                                        (16, "2", True)])
def test_auto_overlaps_only_with_two_cores_for_the_job(monkeypatch, cores: int, omp: str | None, expected: bool):
    # A joblib sweep of n jobs sets OMP_NUM_THREADS = cores // n in its workers: two jobs on two
    # cores then each step and update in turn instead of four threads sharing two cores.
    monkeypatch.setattr(runtime_choice.os, "sched_getaffinity", lambda pid: set(range(cores)))
    if omp is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", omp)
    assert runtime_choice.use_overlap("auto", "cpu") is expected
    assert runtime_choice.use_overlap("auto", "cuda") is False
    assert runtime_choice.use_overlap(True, "cuda") is True
