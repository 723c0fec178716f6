"""The test return of a host that takes one action in every decision, beside a rung's learned hosts.

A learned host whose every test return equals, scenario by scenario and seed by seed, what a host that
always takes one action earns on the same traffic has learned nothing but that action. The test here is
the app's own (`hgm_repro.evaluation.episodes.evaluate`): the same envs, the same number of complete
episodes and the same traffic per seed, with the action fixed instead of chosen.

    python research/studies/one_action.py --bundle docs/results --experiment paper_steps \
        --models min coordinate --out research/study/one_action

Writes `one_action.csv` (per scenario and seed: the one-action host's return, each model's, and the
difference) and prints the largest difference per model.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd
import torch
from tensordict import TensorDictBase
from torch.nn import functional as F

from hgm_repro.contracts.schema import JobConfig
from hgm_repro.evaluation.episodes import Policy, evaluate
from hgm_repro.simulator import N_ACTIONS, Action

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plateau import compose_job  # noqa: E402


def one_action_policy(action: Action, n_envs: int, device: torch.device) -> Policy:
    """A policy that sets `action` for every env, whatever it observes."""
    chosen = F.one_hot(torch.full((n_envs,), int(action), dtype=torch.long, device=device), N_ACTIONS)

    def policy(td: TensorDictBase) -> TensorDictBase:
        return td.set("action", chosen)

    return policy


def job_for(experiment: str, scenario: int, seed: int, extra: list[str] | None = None) -> JobConfig:
    """The resolved job of a non-learning host in `experiment`'s test set-up (its envs and test budget)."""
    return compose_job([f"experiment={experiment}", f"scenario='{scenario}'", f"seed={seed}", "model=random",
                        *(extra or [])])


def one_action_return(job: JobConfig, action: Action) -> dict[str, float]:
    """Mean test return, collisions and speed per episode of the host taking `action` in every decision, on
    the traffic `job.seed`'s test draws."""
    result = evaluate(job, job.scenario, None,
                      host=lambda env: one_action_policy(action, env.simulator.n_envs, env.device))
    return {k: result.means[f"eval/{k}"] for k in ("episode_return", "collisions", "avg_speed_kmh")}


def compare(evals: pd.DataFrame, experiment: str, models: list[str], action: Action,
            extra: list[str] | None = None) -> pd.DataFrame:
    """Per scenario and seed that `models` were tested on in `experiment`: the one-action host's return and
    collisions, each model's return and its difference from the one-action host's."""
    mine = evals[(evals["experiment"] == experiment) & evals["model"].isin(models)]
    if mine.empty:
        raise SystemExit(f"one_action: no test of {models} in experiment '{experiment}' in the bundle")
    rows = []
    for (scenario, seed), group in mine.groupby(["scenario", "seed"]):
        probe = one_action_return(job_for(experiment, int(scenario), int(seed), extra), action)
        row = {"scenario": int(scenario), "seed": int(seed), "one_action_return": probe["episode_return"],
               "one_action_collisions": probe["collisions"]}
        for model, value in group.set_index("model")["episode_return"].items():
            row[f"{model}_return"] = float(value)
            row[f"{model}_difference"] = float(value) - probe["episode_return"]
        rows.append(row)
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bundle", type=Path, required=True, help="a results bundle (its evals.csv)")
    parser.add_argument("--experiment", required=True, help="the preset whose tests to compare (e.g. paper_steps)")
    parser.add_argument("--models", nargs="+", required=True, help="learned models of the bundle")
    parser.add_argument("--action", default="ACCELERATE", choices=[a.name for a in Action],
                        help="the action taken in every decision (default: ACCELERATE)")
    parser.add_argument("--overrides", nargs="*", default=[], help="extra Hydra overrides of the job")
    parser.add_argument("--out", type=Path, required=True, help="folder for one_action.csv")
    args = parser.parse_args(argv)
    table = compare(pd.read_csv(args.bundle / "evals.csv"), args.experiment, args.models, Action[args.action],
                    args.overrides)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "one_action.csv", index=False)
    for model in args.models:
        if f"{model}_difference" in table:
            print(f"{model}: largest |difference| from {args.action} in every decision, over "
                  f"{len(table)} scenario x seed tests: {table[f'{model}_difference'].abs().max():.4f} per episode")


if __name__ == "__main__":
    main()
