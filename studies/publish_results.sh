#!/usr/bin/env bash
# The published results (docs/results/): the paper's grid over seeds 0-4 and the three reference
# hosts at one preset, then the results bundle and the report's figures and tables.
#
#   bash studies/publish_results.sh [extra Hydra overrides, e.g. experiment=paper device=cuda]
#
# Resumable: a run cut off (a session's end, a kill) continues from its checkpoints when the same
# command runs again; finished trainings and evaluations are reused, never redone. The store and
# checkpoints live in studies/runs/results/ (not committed); docs/results/ gets only small files.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
RUNS=studies/runs/results
mkdir -p "$RUNS"
cd "$RUNS"
# scenario first: the first jobs of the sweep are the 15 distinct trainings (model x seed), so
# that the two parallel jobs never wait on the same training.
python -m hgm_repro -m scenario=1,2,3,4,5 model=proposed,min,coordinate seed=0,1,2,3,4 launcher=joblib "$@"
python -m hgm_repro -m scenario=1,2,3,4,5 model=human,idm_mobil,idm_mobil_limits seed=0,1,2,3,4 launcher=joblib "$@"
python -m analysis --write-bundle "$ROOT/docs/results" --out "$ROOT/docs/results/report"
