"""What an installed package relies on: the config lookup, the console script, the citation."""

from __future__ import annotations

import tomllib

import pytest
import yaml

import hgm_repro
from hgm_repro import __main__ as cli
from hgm_repro.contracts.conf_dir import find_conf_dir
from tests.helpers import REPO_ROOT


def test_config_lookup_prefers_the_shipped_copy_then_the_checkout(tmp_path):
    package = tmp_path / "hgm_repro"
    with pytest.raises(FileNotFoundError, match="configs are missing"):
        find_conf_dir(package)
    (tmp_path / "conf").mkdir()
    (tmp_path / "conf" / "config.yaml").write_text("seed: 0\n")
    assert find_conf_dir(package) == tmp_path / "conf"  # a checkout or an editable install
    (package / "conf").mkdir(parents=True)
    (package / "conf" / "config.yaml").write_text("seed: 0\n")
    assert find_conf_dir(package) == package / "conf"  # an installed wheel


def test_the_checkout_finds_its_own_conf():
    assert hgm_repro.CONF_DIR == REPO_ROOT / "conf"


def test_console_script_is_the_module_entry_point():
    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    module, _, function = project["scripts"]["hgm-repro"].partition(":")
    assert module == cli.__name__ == "hgm_repro.__main__"
    assert getattr(cli, function) is cli.main
    assert project["license"] == "MIT" and (REPO_ROOT / "LICENSE").read_text().startswith("MIT License")


def test_citation_cites_the_software_and_the_reproduced_paper():
    cff = yaml.safe_load((REPO_ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software" and cff["license"] == "MIT"
    assert cff["version"] == hgm_repro.__version__
    (paper,) = cff["references"]
    assert paper["type"] == "article"
    assert " ".join(paper["title"].split()) == ("Deep Reinforcement Learning Based High-level Driving Behavior "
                                                "Decision-making Model in Heterogeneous Traffic")
    assert [a["family-names"] for a in paper["authors"]] == ["Bai", "Cai", "Shangguan", "Chai"]
