"""`python -m hgm_repro`: one job (or, with -m, a sweep of jobs) of the reproduction.

Kept thin so that `--help` and `--cfg job` answer without importing torch or MLflow;
the job itself lives in `hgm_repro.app.job`. A single run's config, and each job of a
`-m` grid, is composed and validated here first, so that a bad value or an unknown key stops with
one line on stderr and exit code 2 before Hydra makes its output directory and before any store,
run or checkpoint exists.
"""

from __future__ import annotations

import itertools
import math
import re
import sys
from typing import Any

import hydra
from omegaconf import DictConfig

from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.errors import BAD_INPUT_EXIT

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




def config_problem(overrides: list[str]) -> str | None:
    """Why the config of a single run with these overrides cannot run, in one line; None if it can.

    Hydra's own errors (an unknown group option or key, a malformed override) and the job's
    schema (`hgm_repro.contracts.schema.check_config`) are both checked, without importing torch.
    """
    from hydra import initialize_config_dir

    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return _problem(overrides)


def sweep_problem(overrides: list[str]) -> str | None:
    """`config_problem` for each job of a `-m` sweep over the basic sweeper's grid, before Hydra
    starts: a bad value stops the sweep with one line before any job, store or directory exists.
    Another sweeper (`hparams_search=...`) chooses its jobs as it goes: None, its jobs check themselves."""
    from hydra import initialize_config_dir
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    keys = [o.split("=", 1)[0].lstrip("+~") for o in overrides]
    if any(key in ("hparams_search", "hydra/sweeper") or key.startswith("hydra.sweeper") for key in keys):
        return None
    own = [o for o, key in zip(overrides, keys, strict=True) if not key.startswith("hydra")]  # Hydra's own settings
    try:
        choices = [[f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()] if o.is_sweep_override()
                   else [f"{o.get_key_element()}={o.get_value_element_as_str()}"]
                   for o in OverridesParser.create().parse_overrides(own)]
    except HydraException as error:
        return _one_line(error)
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        for job in _jobs_to_check(choices):
            problem = _problem(job)
            if problem is not None:
                return f"{problem} (in the job {' '.join(job)})"
    return None


def _jobs_to_check(choices: list[list[str]], whole_grid: int = 16) -> list[list[str]]:
    """Every job of a small grid; of a larger one, each swept value once (the others at their first
    value), so that the check stays a second or two: a value bad only in combination stops its job."""
    if math.prod(len(c) for c in choices) <= whole_grid:
        return [list(job) for job in itertools.product(*choices)]
    first = [c[0] for c in choices]
    jobs = [first]
    for i, values in enumerate(choices):
        jobs += [first[:i] + [value] + first[i + 1:] for value in values[1:]]
    return jobs


def _problem(overrides: list[str]) -> str | None:
    from hydra.errors import HydraException, MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    from hgm_repro.contracts.errors import ConfigError

    try:
        return _composed_problem(overrides)
    except MissingConfigException as error:
        return _missing_option(error, overrides)
    except ConfigError as error:
        return str(error)
    except (HydraException, OmegaConfBaseException) as error:
        return _unknown_key(error, overrides) or _one_line(error)


def _composed_problem(overrides: list[str]) -> str | None:
    """As `config_problem`, inside an initialised Hydra: the config's own problems, then keys that
    `+key=value` added (Hydra accepts them; nothing reads them, so a typo would pass silently)."""
    from hydra import compose

    from hgm_repro.contracts.schema import check_config

    added = [o.split("=", 1)[0].lstrip("+") for o in overrides if o.startswith("+") and "=" in o]
    added = [key for key in added if not _is_group(key) and not key.startswith("hydra")]
    cfg = compose("config", overrides=overrides)
    if added:
        return _not_a_key(added[0], [o for o in overrides if o.split("=", 1)[0].lstrip("+") not in added])
    check_config(cfg)
    return None


def _is_group(key: str) -> bool:
    return (CONF_DIR / key.split("@")[0]).is_dir()


def _unknown_key(error: BaseException, overrides: list[str]) -> str | None:
    """Hydra's "Could not override 'learner.lrr'" (a key no config defines) in one line, with the
    nearest key that exists; None for any other error."""
    found = re.search(r"Could not override '([^']+)'", str(error))
    if found is None or "not in struct" not in _one_line(error) and "No match" not in _one_line(error):
        return None
    key = found[1]
    return _not_a_key(key, [o for o in overrides if o.split("=", 1)[0].lstrip("+~") != key])


def _not_a_key(key: str, other_overrides: list[str]) -> str:
    """'`key` is not a config key; did you mean ...?', the nearest of the keys that the config
    composed from `other_overrides` has (config groups included)."""
    import difflib

    from hydra import compose
    from omegaconf import OmegaConf

    from hgm_repro.contracts.config_tree import flatten

    try:
        cfg = compose("config", overrides=other_overrides)
        keys = set(flatten(OmegaConf.to_container(cfg, resolve=False)))
    except Exception:  # noqa: BLE001 - another override is bad too: suggest from the defaults
        keys = set(flatten(OmegaConf.to_container(compose("config"), resolve=False)))
    keys |= {path.name for path in CONF_DIR.iterdir() if path.is_dir()}
    keys |= {k.rsplit(".", 1)[0] for k in keys if "." in k}
    close = difflib.get_close_matches(key, sorted(keys), n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]}?" if close else ""
    return (f"{key} is not a config key{hint} (`python -m hgm_repro --cfg job` lists the keys, "
            "`--help` the groups)")


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


def _is_plain_sweep(argv: list[str]) -> bool:
    flags = [arg for arg in argv if arg.startswith("-")]
    return bool(flags) and all(flag in ("-m", "--multirun") for flag in flags)


@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def _hydra_main(cfg: DictConfig) -> float | None:
    from hgm_repro.app.job import hydra_job

    return hydra_job(cfg)


def main() -> float | None:
    argv = quote_numeric_choices(sys.argv[1:])
    if _is_single_run(argv):
        problem = config_problem(argv)
        if problem is not None:
            print(f"hgm_repro: {problem}", file=sys.stderr)
            raise SystemExit(BAD_INPUT_EXIT)
    elif _is_plain_sweep(argv):
        problem = sweep_problem([arg for arg in argv if not arg.startswith("-")])
        if problem is not None:
            print(f"hgm_repro: {problem}; nothing was launched", file=sys.stderr)
            raise SystemExit(BAD_INPUT_EXIT)
    sys.argv = [sys.argv[0], *argv]
    return _hydra_main()


if __name__ == "__main__":
    main()
