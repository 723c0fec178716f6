#!/usr/bin/env bash
# A labelled variant published beside the paper's grid in docs/results/: MODEL, a conf/model/ config that
# departs from the paper (proposed_enriched: the enriched HGM), over the grid's scenarios and result seeds
# (conf/grid/paper.yaml), in a store of its own; then its runs are read into the grid's bundle beside the
# paper's models and the report is rebuilt. No claim reads a variant: the report tables and draws it.
#
#   bash research/studies/publish_variant.sh MODEL [extra Hydra overrides]
#   bash research/studies/publish_variant.sh proposed_enriched experiment=quick160   # what docs/results holds
#   bash research/studies/publish_variant.sh proposed_enriched experiment=quick160 "scenario='3'"   # one scenario first
#
# Resumable as publish_results.sh is: run again, it reuses finished trainings and evaluations. Published
# again, the variant's runs replace its earlier ones in docs/results/ (the grid's models stay as they are).
set -euo pipefail
cd "$(dirname "$0")/../.."
model=${1:-}
if [ -z "$model" ] || [ ! -f "conf/model/$model.yaml" ]; then
  echo "publish_variant.sh: model '${model}' has no config; allowed: $(cd conf/model && ls -- *.yaml | sed 's/\.yaml$//' | xargs)" >&2
  exit 2
fi
shift
ROOT=$PWD
RUNS=research/studies/runs/variants/$model
mkdir -p "$RUNS"
(cd "$RUNS" && python -m hgm_repro -m grid=paper "model=$model" launcher=joblib "$@")
(cd "$RUNS" && python -m analysis --write-bundle bundle --no-report)
python -m analysis --bundle "$ROOT/docs/results" "$RUNS/bundle" --write-bundle "$ROOT/docs/results" \
  --out "$ROOT/docs/results/report"
