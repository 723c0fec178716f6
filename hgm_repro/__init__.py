"""hgm_repro: the Hyper-Grid Matrix driving-decision paper (Bai et al.), reproduced end to end."""

from pathlib import Path

__version__ = "0.1.0"

PACKAGE_ROOT = Path(__file__).resolve().parent
CONF_DIR = PACKAGE_ROOT.parent / "conf"
