#!/usr/bin/env bash
# The published results (docs/results/): the paper's grid (conf/grid/paper.yaml: seeds 0-4) and the
# three reference hosts (conf/grid/references.yaml) at one preset, then the results bundle and the
# report's figures and tables.
#
#   bash research/studies/publish_results.sh [extra Hydra overrides, e.g. experiment=paper device=cuda]
#
# Resumable: a run cut off (a session's end, a kill) continues from its checkpoints when the same
# command runs again; finished trainings and evaluations are reused, never redone. The store and
# checkpoints live in research/studies/runs/results/ (not committed); docs/results/ gets only small files.
# One model at a time (proposed first, then the reference hosts, then Min's and the Coordinate
# model), so that a run cut off after an hour has whole rows of Table 6, the proposed model's
# first, rather than a third of every row; the bundle and report are rewritten after each model.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
RUNS=research/studies/runs/results
mkdir -p "$RUNS"
cd "$RUNS"
publish() {
  # A report that fails must not stop the grid: the runs are in the store, and the next model's
  # publish (or `python -m analysis` by hand) writes it again.
  python -m analysis --write-bundle "$ROOT/docs/results" --out "$ROOT/docs/results/report" \
    || echo "publishing the bundle and report failed (see above); the grid goes on" >&2
}
for model in proposed references min coordinate; do
  if [ "$model" = references ]; then
    grid=(grid=references)  # conf/grid/references.yaml: the reference hosts in the same cells
  else
    grid=(grid=paper "model=$model")  # conf/grid/paper.yaml, one model at a time
  fi
  # seed varies fastest (the grid's order): the first jobs are the distinct trainings, so that
  # the two parallel jobs never wait on the same training; later scenarios reuse them.
  python -m hgm_repro -m "${grid[@]}" launcher=joblib "$@"
  publish
done
