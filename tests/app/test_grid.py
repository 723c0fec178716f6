"""The paper's grid as one config (`grid=paper`, `grid=references`): the sweep it expands to, and a
command-line value replacing the grid's."""

from __future__ import annotations

from collections import Counter

from hydra import compose, initialize_config_dir
from omegaconf import open_dict

from hgm_repro.app.sweep import _sweep_jobs
from hgm_repro.contracts.config_files import CONF_DIR


def _jobs(*overrides: str, swept: tuple[str, ...] = ()) -> list:
    """The jobs of `-m <overrides> <swept>`: `swept` values (`seed=0,1`) reach only the sweeper."""
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
        with open_dict(cfg):
            cfg.hydra.overrides.task = [*overrides, *swept]
        return _sweep_jobs(cfg)


def test_the_paper_grid_is_three_models_in_five_scenarios_over_five_seeds():
    jobs = _jobs("grid=paper", "experiment=smoke")
    cells = Counter((j.model.name, j.scenario.name, j.seed) for j in jobs)
    assert len(cells) == 75 and set(cells.values()) == {1}
    assert {m for m, _, _ in cells} == {"proposed", "min", "coordinate"}
    assert {s for _, s, _ in cells} == {"1", "2", "3", "4", "5"} and {s for _, _, s in cells} == {0, 1, 2, 3, 4}
    assert [j.seed for j in jobs[:5]] == [0, 1, 2, 3, 4]  # seed fastest: the distinct trainings come first


def test_a_command_line_value_replaces_the_grids():
    jobs = _jobs("grid=paper", "experiment=smoke", "model=proposed", swept=("seed=0,1",))
    assert {(j.model.name, j.seed) for j in jobs} == {("proposed", 0), ("proposed", 1)} and len(jobs) == 10
    references = _jobs("grid=references", "experiment=smoke", "seed=0")
    assert {j.model.name for j in references} == {"human", "idm_mobil", "idm_mobil_limits"}
    assert {j.scenario.name for j in references} == {"1", "2", "3", "4", "5"} and len(references) == 15
