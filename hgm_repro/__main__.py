"""`python -m hgm_repro`: one job (or, with -m, a sweep of jobs) of the reproduction.

Kept thin so that `--help` and `--cfg job` answer without importing torch or MLflow;
the job itself lives in `hgm_repro.experiment.job`. A single run's config is composed and
validated here first, so that a bad value stops with one line on stderr and exit code 2 before
Hydra makes its output directory and before any store, run or checkpoint exists.
"""

from __future__ import annotations

import re
import sys
from typing import Any

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


CONFIG_ERROR_EXIT = 2  # like argparse: the command line asked for something that does not exist


def config_problem(overrides: list[str]) -> str | None:
    """Why the config of a single run with these overrides cannot run, in one line; None if it can.

    Hydra's own errors (an unknown group option or key, a malformed override) and the job's
    schema (`hgm_repro.experiment.schema.validate`) are both checked, without importing torch.
    """
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException, MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    from hgm_repro.experiment.schema import validate
    from hgm_repro.simulator.config import ConfigError

    try:
        with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
            cfg = compose("config", overrides=overrides)
        validate(cfg)
    except MissingConfigException as error:
        return _missing_option(error, overrides)
    except ConfigError as error:
        return str(error)
    except (HydraException, OmegaConfBaseException) as error:
        return _one_line(error)
    return None


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split())
    cause: Any = error.__cause__
    if cause is not None and str(cause) and str(cause) not in text:
        text += ": " + " ".join(str(cause).split())
    return text


def _missing_option(error: Any, overrides: list[str]) -> str:
    """`scenario=7` -> "scenario=7 is not allowed: expected one of 1, 2, 3, 4, 5, train"."""
    missing = str(getattr(error, "missing_cfg_file", "") or "")
    options = getattr(error, "options", None)
    group, _, value = missing.rpartition("/")
    if not group or not options:
        return _one_line(error)
    for override in overrides:  # as the user wrote it, e.g. scenario@train_scenario=7
        key, _, given = override.partition("=")
        if key.lstrip("+~").split("@")[0] == group and given.strip("'\"") == value:
            return f"{key}={value} is not allowed: expected one of {', '.join(map(str, options))}"
    return f"{group}={value} is not allowed: expected one of {', '.join(map(str, options))}"


def _is_single_run(argv: list[str]) -> bool:
    # Flags (-m, --cfg, --help, --config-dir, ...) are Hydra's business: only plain overrides here.
    return not any(arg.startswith("-") for arg in argv)


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def _hydra_main(cfg: DictConfig) -> float | None:
    from hgm_repro.experiment.job import hydra_job

    return hydra_job(cfg)


def main() -> float | None:
    argv = quote_numeric_choices(sys.argv[1:])
    if _is_single_run(argv):
        problem = config_problem(argv)
        if problem is not None:
            print(f"hgm_repro: {problem}", file=sys.stderr)
            raise SystemExit(CONFIG_ERROR_EXIT)
    sys.argv = [sys.argv[0], *argv]
    return _hydra_main()


if __name__ == "__main__":
    main()
