"""What `runtime.update_dtype: auto` and `runtime.overlap: auto` become on the machine a job runs on.

Both settings say how a training runs, never what it learns (they stay outside the train_key, like
`device`), so the choice may depend on the machine:

- the update's precision: bf16 autocast where the device computes bf16 natively (a CUDA GPU with
  bf16, a CPU with AVX512-BF16 or AMX). On this project's CPU it speeds the update up 1.2-1.4x
  (`python -m hgm_repro.bench --only precision`), but on three tuning seeds it did not learn alike
  (research/study.md), so `auto` keeps float32 on CPUs and takes bf16 on CUDA; `bfloat16` asks for it on a CPU.
- overlapping collection with the update (`overlap.py`): on a CPU with at least two cores for this
  job. A joblib sweep gives each of its jobs `cores // n_jobs` (it sets OMP_NUM_THREADS in its
  workers), so two jobs at once on two cores each step and update in turn and never share a core.
"""

from __future__ import annotations

import os
from functools import cache

import torch


@cache
def cpu_has_bf16() -> bool:
    """The CPU computes bf16 natively (oneDNN's check: AVX512-BF16 or AMX)."""
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):  # a build without oneDNN
        return False


def bf16_supported(device: torch.device | str) -> bool:
    device = torch.device(device)
    if device.type == "cuda":
        return torch.cuda.is_available() and torch.cuda.is_bf16_supported()
    return device.type == "cpu" and cpu_has_bf16()


def check_update_dtype(setting: str, device: torch.device | str) -> None:
    """Refuse `runtime.update_dtype=bfloat16` where the device has no native bf16, in one line."""
    if setting == "bfloat16" and not bf16_supported(device):
        what = "this CPU has neither AVX512-BF16 nor AMX" if torch.device(device).type == "cpu" \
            else f"device={device} does not compute bf16"
        raise ValueError(f"runtime.update_dtype=bfloat16 is not allowed here: {what} (emulated bf16 is slower "
                         "than float32); use runtime.update_dtype=float32 or auto")


def update_dtype(setting: str, device: torch.device | str) -> torch.dtype:
    """The dtype the update's forward passes autocast to (float32 = no autocast)."""
    check_update_dtype(setting, device)
    if setting == "bfloat16" or (setting == "auto" and torch.device(device).type == "cuda"
                                 and bf16_supported(device)):
        return torch.bfloat16
    return torch.float32


def cores_for_job() -> int:
    """Cores this process may use: its CPU affinity, capped by OMP_NUM_THREADS where a launcher
    (joblib's workers) or the user set it to share the machine between jobs."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        cores = os.cpu_count() or 1
    limit = os.environ.get("OMP_NUM_THREADS", "")
    if limit.isdigit() and int(limit) > 0:
        cores = min(cores, int(limit))
    return cores


def use_overlap(setting: str | bool, device: torch.device | str) -> bool:
    """`runtime.overlap`: true / false force it; auto overlaps on a CPU with two cores for this job."""
    if isinstance(setting, bool):
        return setting
    if setting != "auto":
        raise ValueError(f"runtime.overlap={setting!r} is not allowed: use auto, true or false")
    return torch.device(device).type == "cpu" and cores_for_job() >= 2
