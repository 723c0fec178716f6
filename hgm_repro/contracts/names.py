"""The names of what a run records, defined once for the simulator, the env, the learner,
evaluation, tracking and analysis (no torch here: analysis imports it too).

Episode metrics are what `HighwaySimulator.step` reports per episode (`StepResult.episode`,
formulas in `simulator.highway.episode_metrics`); evaluation logs them as `eval/<metric>`,
training curves as `train/<metric>`.
"""

from __future__ import annotations

EPISODE_METRICS = ("avg_speed_kmh", "lane_changes", "overtakes", "collisions", "dangerous_actions", "distance_m",
                   "episode_return", "decisions")

# What the report compares between models (an episode's length in decisions is bookkeeping), in
# the order its tables show them: the paper's objective first.
REPORTED_METRICS = ("episode_return", *(m for m in EPISODE_METRICS if m not in ("episode_return", "decisions")))

# The episode metrics a training run logs as `train/<name>` (means over the episodes finished
# since the last log).
TRAINING_CURVE_METRICS = ("avg_speed_kmh", "lane_changes", "overtakes", "episode_return", "collisions")

# The rates a training run logs as `train/<name>` at each log point: env steps per second of wall time, and per
# second of the training process's CPU time (all its threads), which the other load on a shared machine does not
# slow. They time the machine, not the training: two runs of one training differ in them and in nothing else.
TRAINING_RATES = ("steps_per_s", "cpu_steps_per_s")

# Tags every job run carries (architecture.md); analysis filters on them.
RUN_TAGS = ("stage", "model", "scenario", "seed", "train_key", "git_commit", "git_dirty")

# Tags the safest choice (eval.checkpoint=safest) leaves on the TRAINING run, chosen or refused: a refused
# choice opens no test run, so only the training run can say that its passes were driven and none was safe.
# Values: the env steps of the chosen pass, or "refused"; the bar (collisions per episode); the fewest
# collisions per episode any pass had on the validation drives.
SAFEST_TAGS = ("safest_choice", "safest_bar", "safest_lowest_collisions")
SAFEST_REFUSED = "refused"

# The validation return a training run logs (greedy episodes in the training traffic, on seeds
# no test uses): what a hyperparameter search may optimise, unlike any `eval/` value.
VALIDATION_RETURN = "val/episode_return"

# Seed offsets: one job seed gives every stream of randomness its own, never overlapping, seed.
# Test traffic is drawn from other seeds than training traffic (same model seed, other episodes),
# and the same for every model, so that methods meet the same traffic draws.
EVAL_SEED_OFFSET = 100_000
# Validation traffic: seeds that neither training (seed) nor testing (seed + EVAL_SEED_OFFSET) uses.
VAL_SEED_OFFSET = 200_000
# Reselection traffic (eval.checkpoint=reselected): the training traffic again, on seeds that neither
# the validation passes whose best it re-checks nor any test uses, so that it does not re-count their luck.
RESELECT_SEED_OFFSET = 300_000
# Film a different episode than evaluation's first one, but the same one on every run of the job.
GIF_SEED_OFFSET = 7919

# Config keys that moved out of the `learner` group into the groups by concern (`eval`, `runtime`,
# `logging`), as stores written before the move logged them -> where they are now: what reads old
# runs' params translates them with this.
MOVED_CONFIG_KEYS = {
    "learner.test_steps": "eval.test_steps", "learner.test_envs": "eval.test_envs",
    "learner.eval_every": "eval.val_every", "learner.val_envs": "eval.val_envs",
    "learner.val_episodes": "eval.val_episodes",
    "learner.torch_threads": "runtime.torch_threads", "learner.compile": "runtime.compile",
    "learner.cuda_graph": "runtime.cuda_graph", "learner.update_dtype": "runtime.update_dtype",
    "learner.grouped": "runtime.grouped", "learner.replay_frames": "runtime.replay_frames",
    "learner.checkpoint_buffer_max_mb": "runtime.checkpoint_buffer_max_mb",
    "learner.log_every": "logging.log_every", "learner.checkpoint_every": "logging.checkpoint_every",
}


def current_key(key: str) -> str:
    """A logged config key under its name today (`learner.eval_every` -> `eval.val_every`)."""
    return MOVED_CONFIG_KEYS.get(key, key)
