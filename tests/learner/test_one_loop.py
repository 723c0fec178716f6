"""One training loop for one member or many (`hgm_repro.learner.loop`): a solo run is a group of one,
and it trains exactly as the solo loop did before the two loops became one."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import pytest
import torch

from hgm_repro.contracts.checkpoint import EMA_CHECKPOINT, CheckpointMismatchError, load_checkpoint
from hgm_repro.learner import train, train_group
from tests.helpers import REPO_ROOT
from tests.helpers.learner import Recorder, compose_job

PACKAGE = REPO_ROOT / "hgm_repro"

# Logged by the solo loop (learner/dqn.py) before the loops were merged (commit c5566f2), for
# compose_job("seed=3") on this machine's torch: the merged loop must log the same values.
PINNED = {
    32: {"train/episode_return": -25.277102, "train/loss": 3.341458, "train/beta": 0.55, "train/updates": 1.0},
    64: {"train/episode_return": -18.900899, "train/loss": 33.765163, "train/beta": 0.7, "train/updates": 9.0},
    96: {"train/episode_return": -18.118701, "train/loss": 63.454216, "train/beta": 0.85, "train/updates": 17.0},
    128: {"train/episode_return": -16.666607, "train/loss": 27.737614, "train/beta": 1.0, "train/updates": 25.0,
          "val/episode_return": -6.125},
}
PINNED_WEIGHTS = "05938ae99431cb22"  # sha256 of the final network's tensors, in state_dict order
# The same code on a second CPU of this project's machines (Xeon with AMX and avx512_fp16): torch's float32
# kernels round one loss in the last digits differently there, and so the weights. A run matches one machine's pin.
PINNED_OTHER_CPU = {**PINNED, 96: {**PINNED[96], "train/loss": 63.454208}}
PINNED_WEIGHTS_OTHER_CPU = "ac313ea6217956b0"
PINS = ((PINNED, PINNED_WEIGHTS), (PINNED_OTHER_CPU, PINNED_WEIGHTS_OTHER_CPU))


def _weights_digest(network: dict[str, torch.Tensor]) -> str:
    return hashlib.sha256(b"".join(t.numpy().tobytes() for t in network.values())).hexdigest()[:16]


@pytest.fixture(scope="module")
def pinned_run(tmp_path_factory) -> tuple[Path, Recorder]:
    log = Recorder()
    return train(compose_job("seed=3"), tmp_path_factory.mktemp("pinned"), log), log


def test_a_smoke_training_logs_what_the_solo_loop_logged(pinned_run):
    final, log = pinned_run
    logged = dict(log.calls)
    assert sorted(logged) == sorted(PINNED)
    ran = ({step: {k: round(logged[step][k], 6) for k in values} for step, values in PINNED.items()},
           _weights_digest(load_checkpoint(final)["network"]))
    assert ran in PINS, ran


def test_a_group_trains_with_every_learner_option(tmp_path: Path):
    """Polyak targets, the moving average and the frame memory, which only solo runs had, in a group."""
    options = ("learner.target_tau=0.01", "learner.ema_decay=0.9", "runtime.replay_frames=true", "learner.n_step=3",
               "eval.val_every=64", "eval.val_envs=2")
    jobs = [compose_job(*options, f"seed={s}") for s in (0, 1)]
    logs = [Recorder(), Recorder()]
    dirs = [tmp_path / "a", tmp_path / "b"]
    finals = train_group(jobs, dirs, logs)
    networks = []
    for job, directory, final, log in zip(jobs, dirs, finals, logs, strict=True):
        state = load_checkpoint(final, job)
        assert state["finished"] and state["grouped_with"] == [0, 1]
        assert load_checkpoint(directory / EMA_CHECKPOINT, job)["finished"]
        assert "val_ema/episode_return" in log.calls[-1][1] and log.steps("train/loss")
        networks.append(state["network"])
    first = next(iter(networks[0]))
    assert not torch.equal(networks[0][first], networks[1][first])  # each member its own weights


@pytest.mark.parametrize("pattern", [r"optim\.Adam\(", r"\bCollector\("])
def test_one_optimiser_and_one_loop_in_the_package(pattern: str):
    found = [f"{p.relative_to(PACKAGE)}" for p in PACKAGE.rglob("*.py") if re.search(pattern, p.read_text())]
    assert len(found) == 1, found


def test_a_checkpoint_of_an_older_training_identity_is_refused_with_why(pinned_run, tmp_path: Path):
    state = torch.load(pinned_run[0], weights_only=False)
    state["training_config"]["version"] = 2
    state["finished"] = False
    torch.save(state, tmp_path / "last.pt")
    with pytest.raises(CheckpointMismatchError, match="training identity version 2, this code's is 3"):
        train(compose_job("seed=3"), tmp_path, Recorder())


def test_the_log_lines_name_the_greedy_validation_only_on_a_pass(tmp_path: Path, caplog):
    """Without a progress bar (output to a file) the loop writes a line per log interval; the greedy
    validation's return and crash rate belong on the lines of a pass, and no line shows a "nan" for it."""
    caplog.set_level("INFO", logger="hgm_repro.learner.loop")
    train(compose_job("seed=3"), tmp_path, Recorder())
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("train ")]
    assert len(lines) == len(PINNED)
    for step, line in zip(sorted(PINNED), lines, strict=True):
        assert f" {step}/128 env steps" in line and "nan" not in line, line
        if "val/episode_return" in PINNED[step]:
            assert f"greedy validation: return {PINNED[step]['val/episode_return']:.0f}, crashes per episode" in line
        else:
            assert "greedy validation" not in line, line
