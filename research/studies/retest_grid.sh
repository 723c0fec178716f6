#!/usr/bin/env bash
# A published grid trained again and tested three ways, then published into docs/results/.
#
#   bash research/studies/retest_grid.sh MODEL [MODEL ...] [-- extra Hydra overrides]
#   bash research/studies/retest_grid.sh proposed min coordinate                           # the paper's grid
#   bash research/studies/retest_grid.sh proposed_guarded min_guarded coordinate_guarded   # the guarded grid
#
# Each MODEL over the grid's scenarios and result seeds (conf/grid/paper.yaml) with the same configs as
# published, so the same trainings (train_key; one torch thread per joblib job, trained without a stop),
# tested:
#   1. as its preset tests it (best.pt at the quick preset), with the per-episode event columns that the
#      report's crash anatomy reads;
#   2. under the human-driven host's safety layer at test only (eval.host_safety_layer=true, results named
#      <model>_layer_at_test), for a model trained without the layer;
#   3. from its safest kept validation pass (eval.checkpoint=safest, results named <model>_safest); a
#      training with no pass under the bar is refused with a message and has no such test.
# All models' plain tests come first (the crash anatomy of every host), then the probes. Resumable: run
# it again and finished trainings and tests are reused. The store is research/studies/runs/results/ (not
# committed); at the end its bundle, cut to the models and safest seeds whose cells are whole
# (research/studies/whole_cells.py), replaces each (model, preset)'s rows in docs/results/ and the report
# is rebuilt.
set -euo pipefail
cd "$(dirname "$0")/../.."
models=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do
  if [ ! -f "conf/model/$1.yaml" ]; then
    echo "retest_grid.sh: model '$1' has no config; allowed: $(cd conf/model && ls -- *.yaml | sed 's/\.yaml$//' | xargs)" >&2
    exit 2
  fi
  models+=("$1")
  shift
done
[ $# -gt 0 ] && shift  # the --
if [ ${#models[@]} -eq 0 ]; then
  echo "retest_grid.sh: name at least one model, e.g. proposed min coordinate" >&2
  exit 2
fi
ROOT=$PWD
RUNS=research/studies/runs/results
mkdir -p "$RUNS"
cd "$RUNS"
grid() { python -m hgm_repro -m grid=paper launcher=joblib "$@"; }
safest_seed() {
  grid "model=$1" "seed=$2" eval.checkpoint=safest "${@:3}" ||
    echo "retest_grid.sh: $1 seed $2 has no safest test (see the message above)" >&2
}
for model in "${models[@]}"; do
  grid "model=$model" "$@"
done
for model in "${models[@]}"; do
  case "$model" in
    *_guarded) ;;  # trained under the layer already
    *) grid "model=$model" eval.host_safety_layer=true "$@" ;;
  esac
  # Two seeds at once: a seed's first test drives its passes, its other tests wait for that choice.
  safest_seed "$model" 0 "$@" & safest_seed "$model" 1 "$@"; wait
  safest_seed "$model" 2 "$@" & safest_seed "$model" 3 "$@"; wait
  safest_seed "$model" 4 "$@"
done
# Published from a copy cut to what is whole: a model stopped part-way keeps its published rows.
python "$ROOT/research/studies/whole_cells.py" mlflow.db whole/mlflow.db
python -m analysis --tracking-uri "sqlite:///$PWD/whole/mlflow.db" --write-bundle bundle --no-report
cd "$ROOT"
python -m analysis --bundle docs/results "$RUNS/bundle" --write-bundle docs/results --out docs/results/report
