"""hgm_repro: the Hyper-Grid Matrix driving-decision paper (Bai et al.), reproduced end to end.

Importing the package registers `hgm_repro/HeterogeneousHighway-v0` with Gymnasium (as
`import highway_env` does for its envs); it loads neither torch nor the simulator.
"""

from pathlib import Path

from .envs.registration import register_envs

__version__ = "0.1.0"

PACKAGE_ROOT = Path(__file__).resolve().parent


def find_conf_dir() -> Path:
    """The Hydra configs: `hgm_repro/conf` in an installed wheel (setup.py maps the repository's
    `conf/` there), else `conf/` beside the package in a checkout or an editable install."""
    candidates = (PACKAGE_ROOT / "conf", PACKAGE_ROOT.parent / "conf")
    for candidate in candidates:
        if (candidate / "config.yaml").is_file():
            return candidate
    raise FileNotFoundError(f"hgm_repro's configs are missing: none of {[str(c) for c in candidates]} holds "
                            "config.yaml; reinstall the package (pip install .) or run from a checkout")


CONF_DIR = find_conf_dir()

register_envs()
