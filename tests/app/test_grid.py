"""The paper's grid as one config (`grid=paper`, `grid=references`): the sweep it expands to, and a
command-line value replacing the grid's."""

from __future__ import annotations

from collections import Counter

from hydra import compose, initialize_config_dir
from omegaconf import open_dict

from hgm_repro.app.sweep import _sweep_jobs, sweep_overrides
from hgm_repro.contracts.conf_dir import CONF_DIR


def _config(*overrides: str, swept: tuple[str, ...] = ()):
    """The config the sweep callback sees for `-m <overrides> <swept>` (`swept` values reach only the sweeper)."""
    cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
    with open_dict(cfg):
        cfg.hydra.overrides.task = [*overrides, *swept]
    return cfg


def _cells(jobs: list[list[str]]) -> Counter:
    return Counter(tuple(sorted(o for o in job if o.split("=")[0] in ("model", "scenario", "seed"))) for job in jobs)


def test_the_paper_grid_is_three_models_in_five_scenarios_over_five_seeds():
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        jobs = sweep_overrides(_config("grid=paper"))
        references = sweep_overrides(_config("grid=references"))
    cells = _cells(jobs)
    assert len(cells) == 75 and set(cells.values()) == {1}
    values = {key: {o.split("=")[1] for job in jobs for o in job if o.startswith(key + "=")}
              for key in ("model", "scenario", "seed")}
    assert values == {"model": {"proposed", "min", "coordinate"}, "scenario": {"'1'", "'2'", "'3'", "'4'", "'5'"},
                      "seed": {"0", "1", "2", "3", "4"}}
    first = [next(o for o in job if o.startswith("seed=")) for job in jobs[:5]]
    assert first == [f"seed={s}" for s in range(5)]  # seed varies fastest: the distinct trainings come first
    assert {o for job in references for o in job if o.startswith("model=")} == \
        {"model=human", "model=idm_mobil", "model=idm_mobil_limits"} and len(references) == 75


def test_a_command_line_value_replaces_the_grids_and_every_job_validates():
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        jobs = _sweep_jobs(_config("grid=paper", "experiment=smoke", "model=proposed", "scenario='3'",
                                   swept=("seed=0,1",)))
    assert sorted((j.model.name, j.scenario.name, j.seed) for j in jobs) == [("proposed", "3", 0), ("proposed", "3", 1)]
