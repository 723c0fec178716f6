"""From a loaded store to the files in reports/: figures, CSV tables, claims and report.pdf."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from analysis import crashes, equal_terms, ladder, safest, tables
from analysis.claims import claims_table, evaluate_claims
from analysis.curves import area_values, final_values, fluctuation_values
from analysis.discussion import discussion
from analysis.figures import FORMATS, TRAINING_FIGURES, make_figures
from analysis.labels import LEARNED, PROBES, REFERENCE_HOSTS, SCENARIOS, fmt, model_label, ordered_models
from analysis.load import EVAL_METRICS, StoreData, main_experiments
from analysis.markdown import results_markdown
from analysis.pictures import pictures_figure, scenario_pictures
from analysis.report import SHARED_CONFIG, ReportInputs, fmt_estimate, write_report
from analysis.scale import is_smoke, scale_lines
from analysis.scenarios import scenario_mix, with_cv_ratio
from analysis.stats import coverage_text, mean_ci
from hgm_repro.contracts.config_tree import flatten


@dataclass
class Outputs:
    report: Path
    figures: dict[str, dict[str, Path]]
    csvs: list[Path]


def _environment(runs: pd.DataFrame) -> tuple[list[tuple[str, str]], pd.DataFrame | None, str]:
    """Simulator parameters from the runs' logged params, else from conf/simulator/highway.yaml."""
    cols = [c for c in runs.columns if c.startswith("params.simulator.")]
    flat: dict[str, Any] = {}
    source = ""
    if cols:
        first = runs[cols].dropna(how="all")
        if not first.empty:
            row = first.iloc[0]
            flat = {c.removeprefix("params.simulator."): row[c] for c in cols if pd.notna(row[c])}
            source = "from the logged params of the runs"
    if not flat:
        try:
            from hgm_repro.contracts.conf_dir import CONF_DIR

            flat = flatten(yaml.safe_load((Path(CONF_DIR) / "simulator" / "highway.yaml").read_text()))
            source = "from conf/simulator/highway.yaml: the runs did not log them"
        except Exception as exc:  # noqa: BLE001 - the report still builds without this table
            return [], None, f"not available ({type(exc).__name__})"
    vt_rows: dict[str, dict[str, Any]] = {}
    scalars = []
    for key, value in sorted(flat.items()):
        parts = key.split(".")
        if parts[0] == "vehicle_types" and len(parts) == 3:
            vt_rows.setdefault(parts[1], {})[parts[2]] = value
        else:
            scalars.append((key, str(value)))
    vtypes = pd.DataFrame.from_dict(vt_rows, orient="index") if vt_rows else None
    return scalars, vtypes, source


# Keys that differ from run to run by design (each evaluation run's scenario and seed): the test grid shows them.
PER_RUN_KEYS = ("scenario", "seed")
CONFIGS_NOTE = ("Each model's resolved config (of one of its evaluation runs) against the defaults that conf/ of "
                "this checkout composes for that model (python -m hgm_repro model=<name>); scenario and seed vary "
                "from run to run and are left out; (absent) marks a setting the runs predate.")


def _default_configs(models: list[str]) -> dict[str, dict[str, Any]]:
    """The flattened default config of each model that conf/ knows (missing ones are left out)."""
    try:
        from hydra import compose, initialize_config_dir
        from omegaconf import OmegaConf

        from hgm_repro.contracts.conf_dir import CONF_DIR
    except ImportError:
        return {}
    known = [m for m in models if (Path(CONF_DIR) / "model" / f"{m}.yaml").is_file()]
    out = {}
    try:
        with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
            for model in known:
                out[model] = flatten(OmegaConf.to_container(compose("config", overrides=[f"model={model}"])))
    except Exception:  # noqa: BLE001 - a conf/ that does not compose leaves the appendix to say so
        return {}
    return out


def config_differences(configs: dict[str, str]) -> tuple[dict[str, list[tuple[str, str, str]]], str]:
    """Per model, (key, value in its runs, default) for each setting that differs from the defaults, and a
    note saying what the defaults are."""
    order = ordered_models(configs)
    defaults = _default_configs(order)
    out: dict[str, list[tuple[str, str, str]]] = {}
    for model in order:
        try:
            mine = flatten(yaml.safe_load(configs[model]) or {})
        except yaml.YAMLError:
            continue
        base = defaults.get(model)
        if base is None:  # a model conf/ does not know: compared with the first model's runs
            base = defaults.get(order[0]) or {}
        out[model] = [(k, str(mine.get(k, "(absent)")), str(base.get(k, "(absent)")))
                      for k in sorted(set(mine) | set(base))
                      if k.split(".")[0] not in PER_RUN_KEYS and mine.get(k) != base.get(k)]
    note = CONFIGS_NOTE if defaults else ("conf/ could not be composed here, so the appendix has no defaults "
                                          "to compare with.")
    # What every model's runs share (a preset, settings newer than the runs) is printed once, not per model.
    shared = set.intersection(*(set(rows) for rows in out.values())) if len(out) > 1 else set()
    if shared:
        out = {SHARED_CONFIG: sorted(shared), **{m: [r for r in rows if r not in shared] for m, rows in out.items()}}
    return out, note


def _training_numbers(curves: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """For each training figure: per method, seeds, final level and area, each mean [CI] over seeds."""
    out = {}
    for name, (metric, _, _) in TRAINING_FIGURES.items():
        measures = {"Final (last 10 % of steps)": final_values(curves, metric),
                    "Area (mean over common steps)": area_values(curves, metric)}
        if metric == "overtakes":
            measures["Fluctuation (std of bin-to-bin change)"] = fluctuation_values(curves, metric)
        rows = []
        for model in ordered_models(curves.loc[curves["metric"] == metric, "model"]):
            row = {"Method": model_label(model, short=True)}
            for label, values in measures.items():
                v = values.loc[values["model"] == model, "value"].to_numpy(dtype=float)
                e = tables.in_range(mean_ci(v[np.isfinite(v)]), metric)  # a level or a spread of a count or a speed
                row["Seeds"] = str(e.n)
                row[label] = fmt_estimate(e.point, e.low, e.high, e.n, metric, digits=3 if "Fluct" in label else 2)
            rows.append(row)
        if rows:
            frame = pd.DataFrame(rows)
            out[name] = frame[["Method", "Seeds", *measures]]
    return out


def _aggregate_text(evals: pd.DataFrame, scenarios: list[str]) -> pd.DataFrame:
    agg = tables.aggregate(evals, "episode_return", scenarios)
    if agg.empty:
        return agg
    m = "episode_return"
    return pd.DataFrame({
        "Method": [model_label(x, short=True) for x in agg["model"]],
        "Scenarios": agg["scenarios"].astype(str),
        "Mean [95% interval]": [fmt_estimate(r.mean, r.mean_low, r.mean_high, r.min_seeds, m)
                                for r in agg.itertuples()],
        "IQM": [fmt(r.iqm, m) for r in agg.itertuples()],
        "P(Proposed > X)": [fmt(r.p_improve, digits=2) if np.isfinite(r.p_improve) else "-"
                            for r in agg.itertuples()],
    })


def _coverage_notes(data: StoreData) -> list[str]:
    notes = list(data.dropped)
    models = set(data.evals["model"])
    for host in REFERENCE_HOSTS:
        if host not in models:
            notes.append(f"No evaluation runs of the {model_label(host)}: its reference line and the "
                         "comparisons with it are missing.")
    for model in LEARNED:
        if model not in models:
            notes.append(f"No evaluation runs of {model_label(model)}.")
    trained = set(data.curves["model"]) if not data.curves.empty else set()
    for model in LEARNED:
        if model in models and model not in trained:
            notes.append(f"{model_label(model)} has evaluation runs but no training curves in the store.")
    if len(data.git_commits) > 1:
        notes.append(f"The runs come from {len(data.git_commits)} different git commits.")
    mixed = _models_with_several_training_configs(data.runs)
    if mixed:
        notes.append(f"{', '.join(model_label(m, True) for m in mixed)}: one seed has training runs with more than "
                     "one train_key (different training configs); the latest run per method and seed is used.")
    return notes


def _models_with_several_training_configs(runs: pd.DataFrame) -> list[str]:
    """Models where one seed was trained under more than one train_key. A train_key includes the
    seed, so seeds alone give a model several keys: only two keys for one seed are worth a note."""
    train = runs[runs["stage"] == "train"].dropna(subset=["train_key"])
    if train.empty:
        return []
    keys = train.groupby(["model", "seed"])["train_key"].nunique()
    return ordered_models(keys[keys > 1].reset_index()["model"])


def _config_runs(configs: dict[str, str]) -> dict[str, str]:
    """Which run each model's printed config is from (the report prints one per model)."""
    out = {}
    for model, text in configs.items():
        try:
            config = yaml.safe_load(text) or {}
        except yaml.YAMLError:
            continue
        scenario, seed = config.get("scenario", {}).get("name"), config.get("seed")
        if scenario is not None and seed is not None:
            out[model] = (f"of one evaluation run, scenario {scenario}, seed {seed}; its other runs differ in "
                          "scenario and seed only")
    return out


def build_outputs(data: StoreData, out_dir: Path, pictures: bool = True) -> Outputs:
    """Everything `python -m analysis` writes, from one loaded store."""
    out_dir.mkdir(parents=True, exist_ok=True)
    # The ladder reads every preset's runs; every other page one preset per model.
    ladder_section, ladder_numbers, ladder_verdicts, ladder_trainings, ladder_shifts = ladder.section(
        with_cv_ratio(data.evals, data.runs), data.curves, data.episodes, data.runs, data.stopped, out_dir)
    ladder_lines = ladder.page_one_lines(ladder_numbers, set(main_experiments(data.evals).values()),
                                         len(ladder.expected_seeds(data.evals)), ladder.under_way(ladder_trainings))
    data = ladder.main_view(data)
    evals = with_cv_ratio(data.evals, data.runs)  # each scenario placed by the mix its runs logged
    figures = make_figures(data.curves, evals, out_dir)
    ladder_png = next((b.path for b in ladder_section.blocks if b.path is not None), None)
    if ladder_png is not None:
        figures["scale_ladder"] = {ext: ladder_png.with_suffix(f".{ext}") for ext in FORMATS}
    pictures_note = None
    if pictures:
        pics, pictures_note = scenario_pictures(list(SCENARIOS))
        if pics:
            figures["scenes"] = pictures_figure(pics, out_dir / "fig_scenes")
    else:
        pictures_note = "Pictures switched off (--no-pictures)."

    present = set(evals["scenario"])
    scenarios = [s for s in SCENARIOS if s in present] or sorted(present)
    summary = tables.summary(evals)
    grids = {m: tables.wide(summary, m, scenarios) for m in EVAL_METRICS if m in set(summary["metric"])}
    results = evaluate_claims(evals, data.curves)
    counts = tables.seed_counts(evals, list(SCENARIOS) + sorted(present - set(SCENARIOS))) \
        if not evals.empty else pd.DataFrame()
    train_runs = data.runs[data.runs["stage"] == "train"]
    train_seeds = {m: int(train_runs.loc[train_runs["model"] == m, "seed"].nunique())
                   for m in ordered_models(train_runs["model"])}
    scalars, vtypes, env_source = _environment(data.runs)

    csvs = tables.write_csvs(summary, out_dir)
    beating = tables.seeds_beating(evals, scenarios=scenarios, episodes=data.episodes)
    beating_csv = out_dir / "seeds_beating_human.csv"
    beating.to_csv(beating_csv, index=False)
    csvs.append(beating_csv)
    margins = tables.seed_margins(evals, data.episodes)
    if not margins.empty:
        margins_csv = out_dir / "seed_margins_vs_human.csv"
        margins.to_csv(margins_csv, index=False, float_format="%.6g")
        csvs.append(margins_csv)
    claims_csv = out_dir / "claims.csv"
    claims_table(results).to_csv(claims_csv, index=False)
    csvs.append(claims_csv)
    crash_section, crash_table, crash_figure = crashes.section(data.episodes, out_dir)
    if crash_figure is not None:
        figures["crash_anatomy"] = crash_figure
    if not crash_table.empty:
        csvs.append(out_dir / "crash_anatomy.csv")
    for name, frame in (("scale_ladder.csv", ladder_numbers), ("scale_ladder_claims.csv", ladder_verdicts),
                        ("scale_ladder_trainings.csv", ladder_trainings), ("scale_ladder_shifts.csv", ladder_shifts)):
        frame.to_csv(out_dir / name, index=False, float_format="%.6g")
        csvs.append(out_dir / name)
    sections = [s for s in (ladder_section, equal_terms.section(evals, data.curves, results), crash_section,
                            safest.section(evals, data.runs)) if s is not None]

    configs, configs_note = config_differences(data.configs)
    inputs = ReportInputs(
        tracking_uri=data.tracking_uri, experiment=data.experiment, git_commits=data.git_commits,
        seed_counts=counts, train_seeds=train_seeds, notes=_coverage_notes(data),
        figures={k: v["png"] for k, v in figures.items()}, training_numbers=_training_numbers(data.curves),
        env_scalars=scalars, vehicle_types=vtypes, env_source=env_source, pictures_note=pictures_note,
        test_grids=grids, paper_table=tables.paper_table6(), aggregate=_aggregate_text(evals, scenarios),
        beating=tables.beating_grid(beating, scenarios) if not beating.empty else pd.DataFrame(),
        claims=results, discussion=discussion(results, counts, len(train_runs), evals),
        configs=configs, configs_note=configs_note,
        headline=tables.headline(evals[~evals["model"].isin(PROBES)], scenarios), intervals=coverage_text(),
        git_dirty=data.git_dirty, scenario_mix=scenario_mix(data.runs),
        train_keys=sorted(str(k) for k in train_runs["train_key"].dropna().unique()),
        scale=scale_lines(data.configs, evals) + ladder_lines, smoke=is_smoke(data.configs), source=data.source,
        config_runs=_config_runs(data.configs), sections=sections,
    )
    markdown = out_dir / "results.md"
    markdown.write_text(results_markdown(summary, results, data.configs, evals, data.git_commits, figures, out_dir,
                                         beating, sections, ladder_lines))
    csvs.append(markdown)
    report = write_report(inputs, out_dir / "report.pdf")
    return Outputs(report=report, figures=figures, csvs=csvs)
