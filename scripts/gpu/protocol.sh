#!/usr/bin/env bash
# The paper's protocol on a lent GPU machine: Python 3.12 with its own torch (CUDA), no network,
# no torchrl / tensordict / hydra / mlflow. Run from the repository root there:
#
#   bash scripts/gpu/protocol.sh STEP [STEP ...] [-- extra Hydra overrides]
#
# Steps (in this order for the whole protocol; each command stays under LIMIT_S, 540 s by default,
# so that it fits a 10-minute call):
#   check       imports, versions, the CUDA tests and a smoke job on cuda
#   bench       python -m hgm_repro.bench on cuda: simulator at 8,192 and 32,768 envs with camera +
#               HGM, grouped training with 1, 5 and 15 members -> $OUT/bench.jsonl
#   grid        the paper's grid at Table 4 scale, seeds 0-4: 15 trainings (grouped: one process,
#               the seeds of each model in one vmapped update), then 75 test cells
#   references  the human-driven and IDM + MOBIL hosts over the same scenarios and seeds
#   collect     the results bundle and report -> $OUT/results.tgz (docs/results/ layout)
# A step cut off at the time limit is stopped with SIGTERM: trainings write their checkpoints at
# the next safe point and exit; the same command again resumes them (finished work is reused).
# The store and checkpoints live in studies/runs/gpu/ on that machine, kept only while it stays
# warm between calls: run the next command within its idle window.
#
# Before the first call, on a machine with pip and a package index (not the GPU machine):
#   python scripts/gpu/wheelhouse.py        # .whl/, about 40 MiB; the device call carries .whl
# Environment: LIMIT_S (seconds per command, default 540), PYTHON (default python3),
# SITE (where the wheels go, default /tmp/site), TEST_ENVS (test envs per cell, default 1024),
# DEVICE (default cuda), EXPERIMENT (default paper), SEEDS (default 0,1,2,3,4), SCENARIOS
# (default 1,2,3,4,5). A rehearsal on a CPU machine with the wheels for its Python:
#   DEVICE=cpu EXPERIMENT=smoke SEEDS=0,1 SCENARIOS=1 bash scripts/gpu/protocol.sh check grid collect
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
START=$(date +%s)
LIMIT_S=${LIMIT_S:-540}
PY=${PYTHON:-python3}
SITE=${SITE:-/tmp/site}
OUT=${OUT:-$ROOT/studies/runs/gpu/out}
RUNS=$ROOT/studies/runs/gpu
# 1,024 test envs drive one complete episode each per cell: 245,760 decisions, Table 4's 200,000
# rounded up to whole episodes, in one pass (64 envs would take 14 passes).
TEST_ENVS=${TEST_ENVS:-1024}
DEVICE=${DEVICE:-cuda}
EXPERIMENT=${EXPERIMENT:-paper}
SEEDS=${SEEDS:-0,1,2,3,4}
SCENARIOS=${SCENARIOS:-1,2,3,4,5}

steps=()
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then shift; break; fi
  steps+=("$1"); shift
done
extra=("$@")
if [ ${#steps[@]} -eq 0 ]; then
  sed -n '2,29p' "$0"; exit 2
fi
for step in "${steps[@]}"; do
  case $step in
    check|bench|grid|references|collect) ;;
    *) echo "unknown step '$step': use check, bench, grid, references or collect" >&2; exit 2 ;;
  esac
done
mkdir -p "$OUT" "$RUNS"

left() { echo $(( LIMIT_S - ($(date +%s) - START) )); }

install() {
  # The wheels go beside the machine's packages (--target + PYTHONPATH), never over its torch;
  # --no-deps because the resolution was done by wheelhouse.py. Once per warm machine.
  if [ ! -f "$SITE/.hgm_repro_wheels" ]; then
    compgen -G ".whl/*.whl" >/dev/null || {
      echo "no wheels in .whl/: run python scripts/gpu/wheelhouse.py where pip reaches an index, and carry .whl" >&2
      exit 2; }
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .whl/*.whl
    touch "$SITE/.hgm_repro_wheels"
  fi
  export PYTHONPATH="$ROOT:$SITE${PYTHONPATH:+:$PYTHONPATH}"
  export PYTHONUNBUFFERED=1
}

# Runs a command for at most the time left; SIGTERM at the limit, SIGKILL 60 s later.
bounded() {
  local seconds
  seconds=$(left)
  if [ "$seconds" -le 30 ]; then
    echo "time limit reached before: $*; run the same command again" >&2; return 124
  fi
  local rc=0
  timeout --signal=TERM --kill-after=60 "$seconds" "$@" || rc=$?
  if [ $rc -eq 124 ] || [ $rc -eq 137 ] || [ $rc -eq 143 ]; then
    echo "stopped at the time limit (LIMIT_S=$LIMIT_S); finished work is kept: run the same command again to resume" >&2
  fi
  return $rc
}

sweep() {  # the Hydra sweep in the store folder, every job on $DEVICE at Table 4 scale
  (cd "$RUNS" && bounded "$PY" -m hgm_repro -m "scenario=$SCENARIOS" "seed=$SEEDS" "experiment=$EXPERIMENT" "device=$DEVICE" \
     "learner.test_envs=$TEST_ENVS" "$@" "${extra[@]}")
}

install
for step in "${steps[@]}"; do
  echo "== $step ($(left) s left)"
  case $step in
    check)
      "$PY" - <<'EOF' | tee "$OUT/check.txt"
import importlib, sys, torch
print("python", sys.version.split()[0], "| torch", torch.__version__, "| cuda", torch.cuda.is_available(),
      torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")
for name in ("torchrl", "tensordict", "hydra", "omegaconf", "mlflow", "gymnasium", "hgm_repro", "analysis"):
    module = importlib.import_module(name)
    print(f"{name:12s} {getattr(module, '__version__', '')} {module.__file__}")
EOF
      "$PY" -m pip check 2>&1 | tee -a "$OUT/check.txt" || true   # a report, not a gate: --no-deps skipped it
      bounded "$PY" -m pytest -q -p no:cacheprovider tests -k "cuda or CUDA" 2>&1 | tee -a "$OUT/check.txt"
      (cd "$RUNS" && bounded "$PY" -m hgm_repro experiment=smoke "device=$DEVICE" "${extra[@]}") 2>&1 | tail -5 \
        | tee -a "$OUT/check.txt"
      ;;
    bench)
      bounded "$PY" -m hgm_repro.bench --device "$DEVICE" --only simulator --only observations --only learner \
        --only grouped --cuda-n-envs 8192,32768 --members 1,5,15 | tee "$OUT/bench.jsonl"
      ;;
    grid)
      sweep model=proposed,min,coordinate
      ;;
    references)
      sweep model=human,idm_mobil,idm_mobil_limits
      ;;
    collect)
      rm -rf "$RUNS/bundle"
      (cd "$RUNS" && bounded "$PY" -m analysis --write-bundle "$RUNS/bundle" --out "$RUNS/bundle/report")
      tar -czf "$OUT/results.tgz" -C "$RUNS" bundle
      echo "results: $OUT/results.tgz (unpack into docs/results/ here: tar -xzf results.tgz --strip-components=1 -C docs/results)"
      ;;
  esac
done
echo "== done in $(( $(date +%s) - START )) s"
