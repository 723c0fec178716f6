"""What a training cost: the hours it spent training, read from the rates it logged.

A training logs at each log point its rate since the last one: env steps per second of wall time
(`steps_per_s`) and, since it was added, per second of its process's CPU time (`cpu_steps_per_s`), which the
other load on a shared machine does not slow. The hours are the env steps between two log points over the rate
logged at the second, summed: a training stopped in one session and resumed in the next counts only the time
it trained, not the time it lay stopped. CPU hours take the CPU rate where a log point has it and its wall
rate where it does not (a training logged before the CPU rate was, with one torch thread per job). The CPU
time counts every thread of the process, so a CPU hour is a core hour for a job on one core or on two.
"""

from __future__ import annotations

import pandas as pd

from hgm_repro.contracts.names import TRAINING_RATES

WALL_RATE, CPU_RATE = TRAINING_RATES


def rates(curves: pd.DataFrame, cpu: bool = True) -> pd.DataFrame:
    """Per log point (`train_key`, `step`) the rate that times it: the CPU rate where logged and `cpu`, else
    the wall rate; sorted by training and step."""
    columns = ["train_key", "step", "rate"]
    if curves.empty:
        return pd.DataFrame(columns=columns)
    logged = curves[curves["metric"].isin(TRAINING_RATES)]
    if logged.empty:
        return pd.DataFrame(columns=columns)
    wide = logged.pivot_table(index=["train_key", "step"], columns="metric", values="value", aggfunc="last")
    rate = wide[WALL_RATE] if WALL_RATE in wide else pd.Series(float("nan"), index=wide.index)
    if cpu and CPU_RATE in wide:
        rate = wide[CPU_RATE].combine_first(rate)
    out = rate.rename("rate").reset_index().dropna(subset=["rate"])
    return out.sort_values(["train_key", "step"]).reset_index(drop=True)[columns]


def hours_trained(curves: pd.DataFrame, cpu: bool = True) -> pd.Series:
    """Hours spent training per `train_key` (the long curves frame of `StoreData`): CPU hours where logged
    (`cpu`), else wall hours; a training that logged no rate is absent."""
    timed = rates(curves, cpu)
    hours = {}
    for key, group in timed.groupby("train_key"):
        steps = group["step"].astype(float).to_numpy()
        gaps = steps - pd.Series(steps).shift(fill_value=0.0).to_numpy()
        hours[key] = float((gaps / group["rate"].astype(float).to_numpy()).sum() / 3600)
    return pd.Series(hours, dtype=float, name="hours")


def slowest_rate(curves: pd.DataFrame, cpu: bool = True) -> pd.Series:
    """Per `train_key`, the slowest rate (as `rates` picks it) over its log points: what the rest of it goes at.

    Not the last rate: the points logged while the replay memory fills, at the start and again after each resume,
    run without updates at several times the pace of the rest, so a training stopped there would look nearly
    done. The slowest rate errs the other way, by the noise between log points."""
    timed = rates(curves, cpu)
    return timed.groupby("train_key")["rate"].min() if not timed.empty else pd.Series(dtype=float)
