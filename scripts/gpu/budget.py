"""The training budget of the protocol's one call: the largest that the measured rate fits in the time left.

`scripts/gpu/protocol.sh all` runs the paper's grid in one bounded call, so the grid cannot train
for Table 4's 1M env steps: it trains each model's seeds as one group (the models one after the
other) for as many env steps as the time left allows once the test cells and the collection have
their share. This module is that rule, in one place:

    training seconds = seconds left - reserve - test cells x seconds per cell - groups x fixed cost
    env steps        = member rate x safety x training seconds / groups, rounded down to `multiple`,
                       at most the preset's total_steps, at least `floor` (the warm-up and one batch
                       after it: the least that trains at all)

The member rate and the fixed cost come from the bench's rate line (`python -m hgm_repro.bench
--only rate`: one grouped training of the preset, its loop's env steps per second per member and
the time outside the loop); the seconds per test cell from the reference hosts' sweep, which runs
the same cells first, scaled by how much slower the simulator runs with the camera and the HGM
than without (bench lines at the same n_envs). The exploration schedule shrinks with the budget
(epsilon anneals over the same share of the run as the preset says); the other Table 4 values stay.

    python scripts/gpu/budget.py --bench OUT/bench.jsonl --seconds-left 400 --preset paper \\
        --test-cells 75 --reference-seconds 40 --reference-cells 75 --json OUT/budget.json

prints the Hydra overrides (`learner.total_steps=N learner.eps_steps=M`) on stdout and one line
saying what it chose on stderr; --json also writes every input and output.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
# Defaults, each a judgement rather than a measurement (the log says which were used):
SAFETY = 0.8             # the training's checkpoints and a busier machine run slower than the short rate line
CELL_SECONDS = 4.0       # seconds per test cell when the reference sweep measured none
LEARNED_CELL_FACTOR = 2.0  # learned over reference cell when the bench has no same-size pair of lines


@dataclass(frozen=True)
class Budget:
    total_steps: int          # env steps per member (every member of every group)
    eps_steps: int            # epsilon's annealing, scaled with the budget
    fraction_of_paper: float  # total_steps over Table 4's training steps
    fits: bool                # False: even `floor` steps overrun the time left
    seconds_left: float
    training_s: float         # planned for all groups, fixed costs included
    test_s: float             # planned for the learned models' test cells
    reserve_s: float
    member_rate: float        # env steps per second per member, before the safety factor
    groups: int
    note: str


def training_budget(seconds_left: float, member_rate: float, *, groups: int, group_fixed_s: float,
                    test_cells: int, cell_s: float, reserve_s: float, preset_steps: int, preset_eps_steps: int,
                    paper_steps: int, floor: int, multiple: int, safety: float = SAFETY) -> Budget:
    """The rule (see the module's docstring). `member_rate` <= 0 means unmeasured: `floor` steps."""
    if groups < 1 or multiple < 1 or paper_steps < 1 or preset_steps < 1:
        raise ValueError("groups, multiple, paper_steps and preset_steps must be positive")
    floor = min(floor, preset_steps)
    test_s = test_cells * cell_s
    loops_s = seconds_left - reserve_s - test_s - groups * group_fixed_s
    if member_rate > 0:
        fitted = math.floor(member_rate * safety * max(loops_s, 0.0) / groups / multiple) * multiple
    else:
        fitted = 0
    steps = min(fitted, preset_steps)
    fits = member_rate > 0 and steps >= floor
    if member_rate <= 0:
        note = f"no measured rate: the floor of {floor} steps"
    elif not fits:
        note = (f"{fitted} steps fit in {loops_s:.0f} s of training; the floor of {floor} steps is trained anyway "
                "and will run past the plan")
    elif steps == preset_steps:
        note = "the preset's whole budget fits"
    else:
        note = f"the largest multiple of {multiple} env steps that fits"
    steps = max(steps, floor)
    eps_steps = max(1, round(steps * preset_eps_steps / preset_steps))
    rate = member_rate * safety
    training_s = groups * (group_fixed_s + (steps / rate if rate > 0 else 0.0))
    return Budget(total_steps=steps, eps_steps=eps_steps, fraction_of_paper=round(steps / paper_steps, 4), fits=fits,
                  seconds_left=round(seconds_left, 1), training_s=round(training_s, 1), test_s=round(test_s, 1),
                  reserve_s=reserve_s, member_rate=round(member_rate, 2), groups=groups, note=note)


def read_bench(path: Path) -> list[dict[str, Any]]:
    """The bench's JSON lines (a missing file or a cut-off last line gives what is there)."""
    rows = []
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return rows


def rate_line(rows: list[dict[str, Any]], preset: str | None = None) -> dict[str, Any] | None:
    """The last rate line (a grouped training's loop rate per member and fixed cost) of `preset`: the
    bench measures other presets' rates too. A line that names no preset counts for any."""
    lines = [r for r in rows if r.get("member_env_steps_per_s")
             and (preset is None or r.get("preset", preset) == preset)]
    return lines[-1] if lines else None


def learned_cell_factor(rows: list[dict[str, Any]]) -> tuple[float, str]:
    """How much longer a learned model's test cell takes than a reference host's: the simulator
    alone over the simulator with the camera and the HGM, at the largest n_envs both were measured."""
    def rates(what: str) -> dict[int, float]:
        return {r["n_envs"]: r["env_steps_per_s"] for r in rows if r.get("what") == what and r.get("env_steps_per_s")}

    alone, proposed = rates("simulator"), rates("simulator+proposed")
    both = sorted(set(alone) & set(proposed))
    if not both:
        return LEARNED_CELL_FACTOR, f"{LEARNED_CELL_FACTOR} (assumed: no same-size simulator lines)"
    n = both[-1]
    factor = max(1.0, alone[n] / proposed[n])
    return factor, f"{factor:.2f} (simulator alone / with camera + HGM at {n} envs)"


def preset_learner(preset: str, device: str) -> Any:
    """The learner config the grid's jobs get (Hydra's own composition of conf/)."""
    from hydra import compose, initialize_config_dir

    from hgm_repro.contracts.conf_dir import CONF_DIR
    from hgm_repro.contracts.schema import check_config

    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return check_config(compose("config", overrides=[f"experiment={preset}", f"device={device}"])).learner


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bench", type=Path, required=True, help="the bench's JSON lines")
    parser.add_argument("--seconds-left", type=float, required=True, help="seconds left for the grid and the collect")
    parser.add_argument("--preset", default="paper", help="the grid's experiment preset (default: %(default)s)")
    parser.add_argument("--device", default="cuda", help="the grid's device (default: %(default)s)")
    parser.add_argument("--groups", type=int, default=3, help="training groups, one after another (default: 3 models)")
    parser.add_argument("--test-cells", type=int, default=75, help="the learned models' test cells (default: 75)")
    parser.add_argument("--reference-seconds", type=float, default=None,
                        help="wall seconds the reference hosts' sweep took (default: unmeasured)")
    parser.add_argument("--reference-cells", type=int, default=75, help="cells of that sweep (default: 75)")
    parser.add_argument("--reserve", type=float, default=60.0,
                        help="seconds kept for the collect and the sweep's own start (default: %(default)s)")
    parser.add_argument("--safety", type=float, default=SAFETY, help="share of the measured rate planned on "
                        "(default: %(default)s)")
    parser.add_argument("--json", type=Path, default=None, help="also write the inputs and the budget here")
    args = parser.parse_args(argv)

    rows = read_bench(args.bench)
    rate = rate_line(rows, args.preset)
    factor, factor_note = learned_cell_factor(rows)
    if args.reference_seconds is not None and args.reference_cells > 0:
        reference_cell_s = args.reference_seconds / args.reference_cells
        cell_note = f"{reference_cell_s:.2f} s per reference cell (measured) x {factor_note}"
    else:
        reference_cell_s = CELL_SECONDS / LEARNED_CELL_FACTOR
        cell_note = f"{CELL_SECONDS} s per learned cell (assumed: no reference sweep measured)"
        factor = LEARNED_CELL_FACTOR
    learner = preset_learner(args.preset, args.device)
    paper = preset_learner("paper", args.device)
    budget = training_budget(
        args.seconds_left, float(rate["member_env_steps_per_s"]) if rate else 0.0, groups=args.groups,
        group_fixed_s=float(rate["fixed_s"]) if rate else 0.0, test_cells=args.test_cells,
        cell_s=reference_cell_s * factor, reserve_s=args.reserve, preset_steps=learner.total_steps,
        preset_eps_steps=learner.eps_steps, paper_steps=paper.total_steps,
        floor=min(learner.total_steps, learner.warmup_steps + learner.n_envs), multiple=learner.n_envs,
        safety=args.safety)
    print(f"training budget: {budget.total_steps:,} env steps per member, {budget.fraction_of_paper:.2%} of Table 4's "
          f"{paper.total_steps:,} ({budget.note}); rate {budget.member_rate} env steps/s per member x {args.safety} "
          f"safety, {budget.groups} groups one after another, ~{budget.training_s:.0f} s of training, "
          f"~{budget.test_s:.0f} s for {args.test_cells} test cells ({cell_note}), {budget.reserve_s:.0f} s reserved, "
          f"{budget.seconds_left:.0f} s left", file=sys.stderr)
    if args.json:
        record = {**asdict(budget), "preset": args.preset, "paper_steps": paper.total_steps, "rate_line": rate,
                  "cell_s": round(reference_cell_s * factor, 3), "cell_note": cell_note,
                  "test_cells": args.test_cells, "reference_seconds": args.reference_seconds}
        args.json.write_text(json.dumps(record, indent=1) + "\n")
    print(f"learner.total_steps={budget.total_steps} learner.eps_steps={budget.eps_steps}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
