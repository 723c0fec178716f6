"""n-step returns: sums, bootstrap steps and the done flags of a window that runs into a crash."""

import pytest
import torch
from tensordict import TensorDict

from hgm_repro.learner.n_step import NStepReturns


def _steps(t0: int, length: int, terminal_at: int | None = None, envs: int = 2) -> TensorDict:
    """Env e's observation at time t is 100 e + t; reward 1 per step; env 0 crashes at `terminal_at`."""
    t = torch.arange(t0, t0 + length).float()
    obs = (t.view(1, -1) + 100 * torch.arange(envs).view(-1, 1).float()).unsqueeze(-1)
    term = torch.zeros(envs, length, 1, dtype=torch.bool)
    if terminal_at is not None and t0 <= terminal_at < t0 + length:
        term[0, terminal_at - t0] = True
    return TensorDict({"obs": obs, "next": {"obs": obs + 1, "reward": torch.ones(envs, length, 1),
                                            "done": term.clone(), "terminated": term.clone(),
                                            "truncated": torch.zeros_like(term)}}, [envs, length])


def _feed_one_at_a_time(n: int, steps: int, terminal_at: int | None) -> TensorDict:
    returns = NStepReturns(n, gamma=0.5)
    out = [returns(_steps(t, 1, terminal_at)) for t in range(steps)]
    return torch.cat([o for o in out if o is not None], dim=1)


def test_one_step_is_the_identity():
    batch = _steps(0, 3)
    assert NStepReturns(1, 0.9)(batch) is batch


def test_windows_sum_discounted_rewards_and_bootstrap_n_steps_later():
    out = _feed_one_at_a_time(3, 8, terminal_at=None)
    assert out.shape == (2, 6)  # the last n - 1 steps wait for their future
    assert torch.allclose(out["next", "reward"], torch.full((2, 6, 1), 1 + 0.5 + 0.25))
    assert (out["steps_to_next_obs"].reshape(2, 6) == 3).all()
    assert torch.equal(out["next", "obs"], out["obs"] + 3)
    assert not out["next", "terminated"].any()


def test_a_window_that_runs_into_a_crash_is_terminal():
    out = _feed_one_at_a_time(3, 8, terminal_at=3)
    env0 = out[0]
    # Steps 1, 2 and 3 end their windows at the crash (step 3): no bootstrap from the crash state.
    assert env0["next", "terminated"].reshape(-1).tolist() == [False, True, True, True, False, False]
    assert env0["next", "done"].reshape(-1).tolist() == [False, True, True, True, False, False]
    assert env0["steps_to_next_obs"].reshape(-1).tolist() == [3, 3, 2, 1, 3, 3]
    assert env0["next", "reward"].reshape(-1).tolist() == pytest.approx([1.75, 1.75, 1.5, 1.0, 1.75, 1.75])
    # The other env is untouched by env 0's crash.
    assert not out[1]["next", "terminated"].any()


def test_batches_of_several_steps_give_the_same_transitions():
    whole = NStepReturns(3, gamma=0.5)(_steps(0, 8, terminal_at=3))
    one_by_one = _feed_one_at_a_time(3, 8, terminal_at=3)
    for key in ("obs", ("next", "obs"), ("next", "reward"), ("next", "terminated"), "steps_to_next_obs"):
        assert torch.equal(whole[key], one_by_one[key]), key
