"""research/studies/study_arms.py: every arm is a list of overrides that the quick preset accepts (an arm with a
key no config has would fail only after the study has queued it, as r20_enriched once did)."""

from __future__ import annotations

import sys

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf

from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.schema import check_config
from tests.helpers import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "research" / "studies"))
from study_arms import ARMS  # noqa: E402 - research/studies/ is a folder of scripts, not a package


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_every_arm_composes_and_validates_on_the_quick_preset(arm: str) -> None:
    overrides = ["seed=100", "scenario=train", "experiment=quick", "eval.checkpoint=final", *ARMS[arm]]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=overrides)
    check_config(cfg)
    for override in ARMS[arm]:  # each override reached the config, with the value the arm states
        key, value = override.split("=", 1)
        node = OmegaConf.select(cfg, key)
        if isinstance(node, DictConfig):  # a config-group choice (model=min): the chosen config names itself
            assert node.get("name") == value, (arm, override, node.get("name"))
            continue
        assert str(node).lower() == value.lower() or float(node) == float(value), (arm, override, node)


def test_the_reselected_test_trains_exactly_as_the_arm_and_tests_the_reselected_network() -> None:
    from learner_study import KEEP_PASSES, RESELECTED, _command

    from hgm_repro.contracts.train_key import train_key

    def job(extra: list[str]):
        overrides = _command("r20_enriched_160k", 100, "sqlite:///x.db", extra)[3:]  # after python -m hgm_repro
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            return check_config(compose("config", overrides=overrides))

    plain, keeping, reselected = job([]), job(KEEP_PASSES), job(RESELECTED)
    assert train_key(plain) == train_key(keeping) == train_key(reselected)  # one training, as section 11's
    assert plain.eval.checkpoint == "final"  # the study's first test; the quick preset keeps the passes anyway
    assert (keeping.eval.checkpoint, keeping.eval.keep_val_checkpoints) == ("final", True)
    assert (reselected.eval.checkpoint, reselected.eval.keep_val_checkpoints) == ("reselected", True)
