"""`python -m hgm_repro`: one job (or, with -m, a sweep of jobs) of the reproduction.

Kept thin so that `--help` and `--cfg job` answer without importing torch or MLflow;
the job itself lives in `hgm_repro.experiment.job`.
"""

from __future__ import annotations

import re
import sys

import hydra
from omegaconf import DictConfig

from hgm_repro import CONF_DIR

_GROUP_OVERRIDE = re.compile(r"^(?P<key>[~+]?(?P<group>[A-Za-z_][\w/]*)(@[\w.]+)?)=(?P<value>[\d.]+(,[\d.]+)*)$")


def quote_numeric_choices(argv: list[str]) -> list[str]:
    """`scenario=3` -> `scenario='3'`, also inside sweeps (`scenario=1,2,3`).

    Hydra's override parser reads a bare 3 as an int and then refuses it as a config-group
    choice ("Config group override must be a string"), but the paper's scenarios are named
    1..5. Only values of existing config groups are touched; `seed=0,1,2` stays numeric.
    """
    out = []
    for arg in argv:
        m = _GROUP_OVERRIDE.match(arg)
        if m and (CONF_DIR / m["group"]).is_dir():
            arg = m["key"] + "=" + ",".join(f"'{v}'" for v in m["value"].split(","))
        out.append(arg)
    return out


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def _hydra_main(cfg: DictConfig) -> float | None:
    from hgm_repro.experiment.job import hydra_job

    return hydra_job(cfg)


def main() -> float | None:
    sys.argv = [sys.argv[0], *quote_numeric_choices(sys.argv[1:])]
    return _hydra_main()


if __name__ == "__main__":
    main()
