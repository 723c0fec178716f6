"""hgm_repro: the Hyper-Grid Matrix driving-decision paper (Bai et al.), reproduced end to end.

Importing the package registers `hgm_repro/HeterogeneousHighway-v0` with Gymnasium (as
`import highway_env` does for its envs); it loads neither torch nor the simulator.
"""

from .contracts.conf_dir import CONF_DIR, PACKAGE_ROOT, find_conf_dir
from .envs.registration import register_envs

__version__ = "0.1.0"

__all__ = ["CONF_DIR", "PACKAGE_ROOT", "__version__", "find_conf_dir", "register_envs"]

register_envs()
