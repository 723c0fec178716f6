"""A results bundle: everything the report reads from a store, as a few CSV files and a manifest.

A bundle travels without the tracking store and its checkpoints (it is what `docs/results/`
publishes), and `load_bundle` gives back the same `StoreData` that `load_store` gave, so the
report built from a bundle equals the report built from its store.

CSV, not Parquet: the files are small, diff well in git and open in any tool. CSV forgets
dtypes, so the manifest records each column's dtype and `load_bundle` restores it (seeds stay
ints, scenarios stay text, floats round-trip exactly). Two things are not kept: a frame's index
(`StoreData` frames carry a plain range index) and the difference between a missing text value
and an empty one in a column that may hold missing values (both read back as missing).

A bundle written before evals.csv had its `experiment` column gets the column on loading, derived
from its runs.csv the way `load_store` derives it (`analysis.load.with_experiment`).
"""

from __future__ import annotations

import datetime as dt
import json
import re
from pathlib import Path

import pandas as pd

from analysis.load import StoreData, _seed_value
from hgm_repro.contracts.names import REPORTED_METRICS, RUN_TAGS, SAFEST_TAGS

# Bump when a file, a column's meaning or the manifest changes shape; older bundles then fail
# loudly instead of building a wrong report.
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
CONFIG_DIR = "configs"

# StoreData table -> (file, what it holds). The order is the order `--help` lists them in.
TABLE_FILES: dict[str, tuple[str, str]] = {
    "evals": ("evals.csv", "per-run test means, one row per model x scenario x seed x experiment preset: run_id, "
                           "model, scenario, seed, experiment (the run's experiment.name, else its preset tag, else "
                           f"'unknown'), train_key, git_commit, {', '.join(REPORTED_METRICS)}, n_episodes"),
    "episodes": ("episodes.csv", "per-episode test metrics: run_id, model, scenario, seed, episode, "
                                 "the eval metrics of each episode"),
    "curves": ("curves.csv", "training curves, long: run_id, model, seed, train_key, metric, step, value"),
    "runs": ("runs.csv", "one row per kept train/eval run: run_id, run_name, status, start_time, "
                         f"parent_run_id, the tags ({', '.join(RUN_TAGS)}; on a training run also "
                         f"{', '.join(SAFEST_TAGS)}: what its safest choice found), params.<key> (the resolved "
                         "config) and metrics.<key> (last values)"),
    "stopped": ("stopped.csv", "trainings a signal stopped before their last step, to be resumed: run_id, model, "
                               "seed, experiment, train_key, step (the last env step logged), total_steps, steps_per_s "
                               "(the slowest rate it logged, per CPU second where logged), hours (spent training so "
                               "far, CPU hours where logged), stops (times resumed so far)"),
}
# Tables a bundle of an earlier version may lack: read as empty.
OPTIONAL_TABLES = {"stopped"}
CONFIG_NOTE = f"{CONFIG_DIR}/<model>.yaml: each model's resolved config.yaml"
MANIFEST_NOTE = (f"{MANIFEST}: format version, the source tracking URI (its file name only) and experiment, the "
                 "git commits, creation time, runs left out, and each file's rows and column dtypes")


class BundleError(RuntimeError):
    """No bundle at that path, or one this version of the analysis cannot read."""


def describe() -> str:
    """The bundle's files, one per line: `--help` prints this."""
    lines = [f"{name}: {what}" for name, what in TABLE_FILES.values()]
    return "\n".join([*lines, CONFIG_NOTE, MANIFEST_NOTE])


def _config_file(model: str) -> str:
    # Model names come from config file names, but a path separator would escape the directory.
    return f"{CONFIG_DIR}/{re.sub(r'[^A-Za-z0-9_.-]', '_', model)}.yaml"


def _previous_files(directory: Path) -> list[Path]:
    """The files an earlier bundle in `directory` wrote, so that a rewrite leaves none of them stale."""
    try:
        manifest = json.loads((directory / MANIFEST).read_text())
    except (OSError, ValueError):
        return []
    names = [t.get("file") for t in manifest.get("tables", {}).values()] + list(manifest.get("configs", {}).values())
    return [directory / n for n in names if isinstance(n, str) and "/.." not in f"/{n}"]


def portable_uri(uri: str) -> str:
    """The tracking URI without the writing machine's directories: `sqlite:////abs/dir/mlflow.db` becomes
    `sqlite:///mlflow.db`, a file path its name; a server URI stays. Several, joined by '; ', one by one."""
    parts = []
    for part in str(uri).split("; "):
        if part.startswith("sqlite:///"):
            parts.append("sqlite:///" + Path(part.removeprefix("sqlite:///")).name)
        elif part.startswith("file:"):
            parts.append(Path(part.removeprefix("file:").lstrip("/") or ".").name)
        elif "://" in part:
            parts.append(part)
        else:
            parts.append(Path(part).name)
    return "; ".join(parts)


def write_bundle(data: StoreData, directory: Path | str) -> list[Path]:
    """Write `data` as a bundle into `directory` (created if needed); returns the files written."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    for old in _previous_files(directory):
        old.unlink(missing_ok=True)
    written: list[Path] = []
    tables = {}
    for field_name, (name, what) in TABLE_FILES.items():
        frame: pd.DataFrame = getattr(data, field_name)
        path = directory / name
        frame.to_csv(path, index=False)
        written.append(path)
        tables[field_name] = {"file": name, "holds": what, "rows": len(frame),
                              "columns": {str(c): str(t) for c, t in frame.dtypes.items()}}
    configs = {}
    for model, text in sorted(data.configs.items()):
        name = _config_file(model)
        path = directory / name
        path.parent.mkdir(exist_ok=True)
        path.write_text(text)
        written.append(path)
        configs[model] = name
    manifest = {
        "format_version": FORMAT_VERSION,
        "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        # A bundle travels: the store's directory on the machine that wrote it means nothing elsewhere.
        "tracking_uri": portable_uri(data.tracking_uri),
        "experiment": data.experiment,
        "git_commits": data.git_commits,
        "git_dirty": data.git_dirty,
        "dropped": list(data.dropped),
        "tables": tables,
        "configs": configs,
    }
    path = directory / MANIFEST
    path.write_text(json.dumps(manifest, indent=2) + "\n")
    written.append(path)
    return written


def _restore(raw: pd.Series, dtype: str) -> pd.Series:
    """One column, read as text with nothing turned into NaN, back to the dtype it was written with."""
    missing = raw.eq("")
    if dtype == "string":  # a StringDtype column (the runs' scenario) holds "" as a value
        return raw.astype("string")
    if dtype.startswith(("int", "uint")):
        return raw.astype(dtype)
    if dtype.startswith("float"):
        # Python's float() reads the shortest repr that to_csv wrote back to the same double.
        return raw.mask(missing, "nan").map(float).astype(dtype)
    if dtype == "bool":
        return raw.map({"True": True, "False": False}).astype(bool)
    if dtype == "str":  # pandas' default text dtype, missing values as NaN
        return raw.mask(missing).astype("str")
    values = raw.astype(object).mask(missing, None)
    if raw.name == "seed":  # a seed tag is an int where it parses as one, as load_store reads it
        values = values.map(lambda v: v if v is None else _seed_value(v))
    return values


def _read_table(directory: Path, name: str, columns: dict[str, str], rows: int | None = None) -> pd.DataFrame:
    path = directory / name
    if not path.exists():
        raise BundleError(f"the bundle at {directory} lacks {name}, which its {MANIFEST} lists")
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (ValueError, UnicodeDecodeError) as exc:  # pandas' ParserError and EmptyDataError are ValueErrors
        raise BundleError(f"{path} is damaged ({_first_line(exc)}): write the bundle again") from exc
    if list(frame.columns) != list(columns):
        raise BundleError(f"{path} has columns {list(frame.columns)}, its {MANIFEST} says {list(columns)}")
    if rows is not None and len(frame) != rows:
        raise BundleError(f"{path} is damaged: it holds {len(frame)} rows, its {MANIFEST} says {rows} (a truncated "
                          "copy?); write the bundle again")
    restored = {}
    for column, dtype in columns.items():
        try:
            restored[column] = _restore(frame[column], dtype)
        except (ValueError, TypeError) as exc:  # a truncated or edited file: a value that is not a `dtype`
            raise BundleError(f"{path} is damaged: column {column!r} should hold {dtype} values "
                              f"({_first_line(exc)}); write the bundle again") from exc
    return pd.DataFrame(restored, columns=list(columns))


def _first_line(error: BaseException) -> str:
    return " ".join(str(error).split())[:160] or type(error).__name__


def load_bundle(directory: Path | str) -> StoreData:
    """Read a bundle written by `write_bundle`. Raises `BundleError` when there is none or it is of another format."""
    directory = Path(directory)
    manifest_path = directory / MANIFEST
    if not manifest_path.is_file():
        what = "does not exist" if not directory.exists() else \
            "is empty" if directory.is_dir() and not any(directory.iterdir()) else f"has no {MANIFEST}"
        raise BundleError(f"no results bundle at {directory}: it {what} (write one with "
                          "`python -m analysis --write-bundle DIR`)")
    try:
        manifest = json.loads(manifest_path.read_text())
    except ValueError as exc:
        raise BundleError(f"{manifest_path} is not valid JSON: {_first_line(exc)}") from exc
    version = manifest.get("format_version")
    if version != FORMAT_VERSION:
        raise BundleError(f"the bundle at {directory} has format version {version}, this analysis reads format "
                          f"version {FORMAT_VERSION}: rebuild the bundle from its store with this version, or "
                          "use the analysis of the commit that wrote it")
    try:
        listed = {field_name: (manifest["tables"][field_name]["file"], manifest["tables"][field_name]["columns"],
                               manifest["tables"][field_name].get("rows"))
                  for field_name in TABLE_FILES
                  if not (field_name in OPTIONAL_TABLES and field_name not in manifest["tables"])}
    except (KeyError, TypeError) as exc:
        raise BundleError(f"{manifest_path} lacks the entry {_first_line(exc)} of its tables: the bundle is "
                          "damaged; write it again") from exc
    tables = {field_name: _read_table(directory, *entry) for field_name, entry in listed.items()}
    configs = {}
    for model, name in manifest.get("configs", {}).items():
        try:
            configs[model] = (directory / name).read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise BundleError(f"{directory / name} cannot be read ({type(exc).__name__}), though its {MANIFEST} "
                              "lists it: the bundle is damaged; write it again") from exc
    # The source store's path is the author's machine's: the report names the bundle instead.
    source = f"results bundle {directory.resolve().name}/ (experiment {manifest.get('experiment')})"
    return StoreData(tracking_uri=manifest["tracking_uri"], experiment=manifest["experiment"], configs=configs,
                     dropped=list(manifest.get("dropped", [])), source=source, **tables)

