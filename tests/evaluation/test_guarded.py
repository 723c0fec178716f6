"""The learned hosts under the human-driven host's safety layer: model=<method>_guarded in training and
test (its own training identity and name), and eval.host_safety_layer, the layer at test only."""

from __future__ import annotations

import pytest
import torch

from hgm_repro.contracts.errors import ConfigError
from hgm_repro.contracts.schema import results_model_name
from hgm_repro.contracts.train_key import train_key
from hgm_repro.envs import make_env
from hgm_repro.evaluation import evaluate
from hgm_repro.learner import train
from hgm_repro.simulator import HOST, Action
from tests.helpers.learner import Recorder, compose_cfg, compose_job
from tests.helpers.sim import calm, empty_road, place


@pytest.mark.parametrize("method", ["proposed", "min", "coordinate"])
def test_a_guarded_model_is_the_method_under_the_layer_with_its_own_name_and_training(method):
    plain, guarded = compose_job(f"model={method}"), compose_job(f"model={method}_guarded")
    assert guarded.model.name == f"{method}_guarded" and guarded.model.safety_layer
    assert (guarded.model.network, guarded.model.streams) == (plain.model.network, plain.model.streams)
    assert guarded.simulator.host_safety_layer and not plain.simulator.host_safety_layer
    assert train_key(guarded) != train_key(plain)  # it learns something else
    assert results_model_name(guarded) == f"{method}_guarded"


def test_the_paper_models_keep_their_training_identity():
    # The guarded option is absent from the paper's models' configs: their resolved model node, and so
    # their train_key, are what they were before it existed.
    assert "safety_layer" not in compose_cfg("model=proposed").model
    assert train_key(compose_cfg("model=proposed")) == train_key(compose_job("model=proposed"))


def _crash_scene(env) -> None:
    """A car alongside on the left, the host's left lane change would run into it."""
    sim = calm(empty_road(env.simulator, host_lane=2, host_speed=60 / 3.6))
    place(sim, 1, lon=1.0, lane=1, speed=60 / 3.6)


@pytest.mark.parametrize("model, crashes", [("proposed", True), ("proposed_guarded", False)])
def test_the_layer_refuses_the_guarded_host_a_lane_change_that_crashes_the_unguarded_one(model, crashes):
    # The env a guarded job builds (training, validation and test all build it through make_env).
    job = compose_job(f"model={model}")
    env = make_env(job, job.train_scenario, n_envs=1, seed=0)
    _crash_scene(env)
    crashed = False
    for _ in range(12):  # the policy insists on changing left: only the layer stands between it and the car
        result = env.simulator.step(torch.tensor([int(Action.LANE_LEFT)]))
        crashed |= bool(result.collision[0])
        if crashed:
            break
    assert crashed is crashes
    if not crashes:
        assert int(env.simulator.state.target_lane[0, HOST]) == 2  # never began it
        assert float(env.simulator.state.ep_refused_gap[0]) > 0


def test_setting_the_simulators_layer_under_a_learned_model_is_refused():
    with pytest.raises(ConfigError, match=r"simulator.host_safety_layer=true is not allowed.*proposed_guarded"):
        compose_job("simulator.host_safety_layer=true")


@pytest.mark.parametrize("overrides, says", [
    (["model=human", "eval.host_safety_layer=true"], "its driver decides"),
    (["model=proposed_guarded", "eval.host_safety_layer=true"], "drives under the layer already"),
    (["model=human", "+model.safety_layer=true"], "model.safety_layer=true is not allowed for the non-learning"),
    (["eval.checkpoint=safest", "eval.keep_val_checkpoints=false"], "eval.checkpoint=safest is not allowed"),
    (["eval.safest_episodes=100"], "eval.safest_episodes=100 is not allowed: must be >= 256"),
    (["eval.safest_max_collisions=-0.1"], "eval.safest_max_collisions=-0.1 is not allowed: must be >= 0"),
])
def test_bad_values_are_refused_with_one_clear_message(overrides, says):
    with pytest.raises(ConfigError) as refused:
        compose_job(*overrides)
    message = str(refused.value)
    assert message.startswith("invalid config: ") and "\n" not in message  # one problem, one line
    assert says in message


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return train(compose_job(), tmp_path_factory.mktemp("probe"), Recorder())


def test_the_probe_tests_an_unguarded_training_under_the_layer_and_names_it_so(checkpoint):
    plain = compose_job("eval.test_steps=80")
    probe = compose_job("eval.test_steps=80", "eval.host_safety_layer=true")
    assert train_key(probe) == train_key(plain)  # the same training: only the test differs
    assert results_model_name(probe) == "proposed_layer_at_test" != results_model_name(plain)
    assert not probe.simulator.host_safety_layer  # training and validation stay without it
    under = evaluate(probe, probe.scenario, checkpoint).episodes
    as_trained = evaluate(plain, plain.scenario, checkpoint).episodes
    # Under the layer the host is guarded (the Krauss speed and gap acceptance); without it, never refused.
    assert as_trained["lane_changes_refused_gap"].sum() == as_trained["lane_changes_refused_parity"].sum() == 0
    assert under["collisions"].sum() == 0
    assert not under.equals(as_trained)
