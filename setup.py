"""What pyproject.toml cannot say: the Hydra configs ship inside the package as `hgm_repro/conf`
while the repository keeps them at its root in `conf/` (where Hydra users look for them).

pyproject's `packages.find` cannot add a package from another directory, so the package list
lives here; everything else about the build is in pyproject.toml. `hgm_repro.find_conf_dir()`
finds the configs in both places.
"""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["hgm_repro*", "baselines*", "analysis*"]), "hgm_repro.conf"],
    package_dir={"hgm_repro.conf": "conf"},
)
