#!/usr/bin/env bash
# The paper's protocol on a lent GPU machine, in ONE call: Python 3.12 with its own torch (CUDA), no
# network, no torchrl / tensordict / hydra / mlflow, about 15 minutes of machine time in all (every
# start and idle wait counted), 10 minutes per command, the machine given back 30 s after a command
# ends (a second call finds a bare machine). Run from the repository root there, with .whl carried:
#
#   bash scripts/gpu/protocol.sh all [-- extra Hydra overrides]      # the whole protocol, one call
#   bash scripts/gpu/protocol.sh STEP [STEP ...] [-- overrides]       # some steps, in the order given
#
# all = check bench references grid collect, the whole under LIMIT_S (540 s: a 10-minute call):
#   check       imports, versions, a simulator step with camera + HGM on $DEVICE; on CUDA, the CUDA-vs-CPU
#               simulator test and a smoke training on CUDA, eager and with its update as a CUDA graph
#   bench       at most BENCH_S: simulator at 8,192 envs, with camera + HGM at 8,192 and 32,768; the rate
#               line (the seeds of one model trained as a group at $EXPERIMENT, its loop's env steps/s per
#               member, the update as the grid runs it); one grouped update of every seed of the grid (15
#               members) in each of UPDATE_MODES; then a rate line for each preset of RATE_PRESETS (what
#               a training of the CPU's scale-ladder rungs would cost on this device), as time allows
#   references  the human-driven and IDM + MOBIL hosts in every scenario and seed (no training)
#   grid        the 3 models x seeds, each model's seeds trained as one group, at the largest training
#               budget the measured rate fits in the time left (scripts/gpu/budget.py: logged, with the
#               fraction of Table 4's 1M steps), each member's update a CUDA graph (CUDA_GRAPH), then
#               their test cells in every scenario
#   collect     the results bundle and its report -> $OUT/results.tgz and $OUT/report.pdf
# Everything reaches $OUT as it goes: protocol.log (this output), bench.jsonl line by line,
# budget.json once chosen; the grid stops RESERVE_S before the limit so that collect always runs.
# A step cut off at the limit gets SIGTERM: trainings write last.pt at the next safe point and
# exit; on a machine kept warm, the same command again resumes (finished work is reused).
#
# Before the call, on a machine with pip and a package index (not the GPU machine):
#   python scripts/gpu/wheelhouse.py        # .whl/, about 40 MiB; the device call carries .whl
# Environment: LIMIT_S (seconds in all, default 540), BENCH_S (cap of bench, default 150), RESERVE_S
# (kept for collect, default 60), PYTHON (default python3), SITE (where the wheels go, /tmp/site),
# DEVICE (cuda), EXPERIMENT (paper), SEEDS (0,1,2,3,4; 0,1 on cpu), SCENARIOS (1,2,3,4,5; 1,2 on cpu),
# TEST_ENVS (test envs per cell: 256; 4 on cpu), JOBS (test cells at once: 8; 2 on cpu), REFERENCES_S
# (cap of references: a third of the time left), TOTAL_STEPS (a training budget instead of the
# rule's), CUDA_GRAPH (the training's update as a CUDA graph: true; false on cpu), UPDATE_MODES (the
# grouped update's modes: eager,bf16,cuda_graph; eager on cpu), RATE_PRESETS (extra rate lines:
# paper_steps paper_pixels; none on cpu). Without .whl the script uses the packages its
# Python already has. A rehearsal of the same steps on a CPU machine, a smaller grid, the same limit:
#   DEVICE=cpu EXPERIMENT=smoke bash scripts/gpu/protocol.sh all
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
START=$(date +%s)
LIMIT_S=${LIMIT_S:-540}
BENCH_S=${BENCH_S:-150}
RESERVE_S=${RESERVE_S:-60}
PY=${PYTHON:-python3}
SITE=${SITE:-/tmp/site}
OUT=${OUT:-$ROOT/runs/gpu/out}
RUNS=${RUNS:-$ROOT/runs/gpu}  # the store, checkpoints and bundle (on the machine, never in $OUT)
DEVICE=${DEVICE:-cuda}
EXPERIMENT=${EXPERIMENT:-paper}
if [ "$DEVICE" = cpu ]; then cpu=1; else cpu=0; fi
# The paper's grid is one config (conf/grid/paper.yaml, references.yaml), read here as it is written.
grid_value() { sed -n "s/^ *$2: *//p" "conf/grid/$1.yaml" | tr -d "\"'"; }
# A CPU rehearsal runs every step on a smaller grid: on a 2-core CPU a test cell takes seconds (half
# a minute with 1,024 envs), so 150 of them would not fit, and its 2 cores run 2 cells at once.
SEEDS=${SEEDS:-$([ $cpu = 1 ] && echo 0,1 || grid_value paper seed)}
SCENARIOS=${SCENARIOS:-$([ $cpu = 1 ] && echo 1,2 || grid_value paper scenario)}
# 256 test envs drive one complete episode each per cell: 61,440 decisions in one pass. 1,024 envs give
# Table 4's 200,000 (245,760), but one call on an H200 spent the time its grid needed to train on
# such cells: a grid at a fraction of Table 4's steps is better spent on training than on test decisions.
TEST_ENVS=${TEST_ENVS:-$([ $cpu = 1 ] && echo 4 || echo 256)}
JOBS=${JOBS:-$([ $cpu = 1 ] && echo 2 || echo 8)}
# The update as a CUDA graph made one grouped update 4.9x as fast as eager on an H200; the training
# loop is update-bound there, so the grid and its rate line run it so.
CUDA_GRAPH=${CUDA_GRAPH:-$([ $cpu = 1 ] && echo false || echo true)}
# torch.compile did not finish its first grouped update within the bench's 150 s on an H200.
UPDATE_MODES=${UPDATE_MODES:-$([ $cpu = 1 ] && echo eager || echo eager,bf16,cuda_graph)}
RATE_PRESETS=${RATE_PRESETS:-$([ $cpu = 1 ] && echo "" || echo "paper_steps paper_pixels")}
LEARNED=$(grid_value paper model)
REFERENCES=$(grid_value references model)
count() { local IFS=,; set -- $1; echo $#; }
N_SEEDS=$(count "$SEEDS")
N_SCENARIOS=$(count "$SCENARIOS")
N_LEARNED=$(count "$LEARNED")

steps=()
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then shift; break; fi
  if [ "$1" = all ]; then steps+=(check bench references grid collect); else steps+=("$1"); fi
  shift
done
extra=("$@")
if [ ${#steps[@]} -eq 0 ]; then
  sed -n '2,40p' "$0"; exit 2
fi
for step in "${steps[@]}"; do
  case $step in
    check|bench|references|grid|collect) ;;
    *) echo "unknown step '$step': use all, or check, bench, references, grid, collect" >&2; exit 2 ;;
  esac
done
mkdir -p "$OUT" "$RUNS"
# The log reaches $OUT line by line: a call cut off at its limit still returns it.
exec > >(tee -a "$OUT/protocol.log") 2>&1
log_tee=$!

left() { echo $(( LIMIT_S - ($(date +%s) - START) )); }

install() {
  # The wheels go beside the machine's packages (--target + PYTHONPATH), never over its torch;
  # --no-deps because the resolution was done by wheelhouse.py. Once per machine.
  export PYTHONPATH="$ROOT:$SITE${PYTHONPATH:+:$PYTHONPATH}"
  export PYTHONUNBUFFERED=1
  if compgen -G ".whl/*.whl" >/dev/null; then
    if [ ! -f "$SITE/.hgm_repro_wheels" ]; then
      "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .whl/*.whl
      mkdir -p "$SITE" && touch "$SITE/.hgm_repro_wheels"
    fi
  elif "$PY" -c "import torchrl, tensordict, hydra, mlflow" 2>/dev/null; then
    echo "no wheels in .whl/: using the packages $PY already has"
  else
    echo "no wheels in .whl/ and $PY lacks torchrl / tensordict / hydra / mlflow: run python" \
         "scripts/gpu/wheelhouse.py where pip reaches an index, and carry .whl" >&2
    exit 2
  fi
}

# Runs a command for at most `seconds` (default: the time left); SIGTERM then, SIGKILL 30 s later.
bounded() {
  local seconds=$1; shift
  if [ "$seconds" -le 20 ]; then
    echo "time limit reached before: $*" >&2; return 124
  fi
  local rc=0 pid
  # timeout leads its own process group; once it returns, whatever of that group is left (a sweep's
  # joblib workers outlive their parent) is killed, so that the next step has the machine to itself.
  timeout --signal=TERM --kill-after=30 "$seconds" "$@" &
  pid=$!
  wait $pid || rc=$?
  kill -KILL -- -$pid 2>/dev/null || true
  if [ $rc -eq 124 ] || [ $rc -eq 137 ] || [ $rc -eq 143 ]; then
    echo "stopped after $seconds s (LIMIT_S=$LIMIT_S): finished work is kept" >&2
  fi
  return $rc
}

sweep() {  # a Hydra sweep in the store folder for at most $1 s; never past RESERVE_S before the limit
  local seconds=$1 models=$2; shift 2
  if [ "$seconds" -gt $(( $(left) - RESERVE_S )) ]; then seconds=$(( $(left) - RESERVE_S )); fi
  (cd "$RUNS" && bounded "$seconds" "$PY" -m hgm_repro -m "model=$models" "scenario=$SCENARIOS" \
     "seed=$SEEDS" "experiment=$EXPERIMENT" "device=$DEVICE" "eval.test_envs=$TEST_ENVS" \
     launcher=joblib "hydra.launcher.n_jobs=$JOBS" tracking.log_gif=false tracking.log_model=false \
     "$@" "${extra[@]}")
}

echo "== protocol: ${steps[*]} on $DEVICE, experiment=$EXPERIMENT, seeds $SEEDS, scenarios $SCENARIOS," \
     "$TEST_ENVS test envs per cell, LIMIT_S=$LIMIT_S, started $(date -u +%FT%TZ)"
install
status=0
for step in "${steps[@]}"; do
  echo "== $step ($(left) s left)"
  case $step in
    check)
      "$PY" - "$DEVICE" <<'EOF' || status=1
import importlib, sys, time, torch
device = sys.argv[1]
print("python", sys.version.split()[0], "| torch", torch.__version__, "| cuda", torch.cuda.is_available(),
      torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")
for name in ("torchrl", "tensordict", "hydra", "omegaconf", "mlflow", "gymnasium", "hgm_repro", "analysis"):
    module = importlib.import_module(name)
    print(f"{name:12s} {getattr(module, '__version__', '')} {module.__file__}")
from hgm_repro.bench import bench_observations
start = time.perf_counter()
row = bench_observations("proposed", 64, torch.device(device), seconds=0.5)
print(f"simulator + camera + HGM, 64 envs on {device}: {row['env_steps_per_s']} env steps/s "
      f"({time.perf_counter() - start:.1f} s with set-up)")
EOF
      if [ "$DEVICE" != cpu ]; then
        # The code paths only a GPU runs: the simulator on CUDA against the CPU, and a training whose
        # update is eager or a CUDA graph (torch.compile's first call takes minutes: the bench tries it).
        bounded 120 "$PY" -m pytest -q -p no:cacheprovider tests/simulator/test_simulator.py \
          tests/learner/test_learner.py -k "cpu_and_cuda_agree or smoke_training_on_cuda[eager]" || status=1
        if [ "$CUDA_GRAPH" = true ] && ! bounded 90 "$PY" -m pytest -q -p no:cacheprovider \
             tests/learner/test_learner.py -k "smoke_training_on_cuda[cuda_graph]"; then
          # A failing CUDA graph must not cost the call its grid: the rest runs eagerly.
          echo "the training with its update as a CUDA graph failed: bench and grid run it eagerly (CUDA_GRAPH=false)" >&2
          CUDA_GRAPH=false; status=1
        fi
      fi
      ;;
    bench)
      if [ $cpu = 1 ]; then sizes=(--n-envs 256 --obs-n-envs 256 --rate-steps 64 --seconds 1)
      else sizes=(--cuda-n-envs 8192 --obs-n-envs 8192,32768 --rate-steps 4096 --seconds 2); fi
      cap=$(left)
      if [ "$cap" -gt "$BENCH_S" ]; then cap=$BENCH_S; fi
      bench_end=$(( $(date +%s) + cap ))
      bounded "$cap" "$PY" -m hgm_repro.bench --device "$DEVICE" --only simulator --only observations \
        --variants proposed --only rate --only grouped_update "${sizes[@]}" --preset "$EXPERIMENT" \
        --rate-members "$N_SEEDS" --rate-overrides "runtime.cuda_graph=$CUDA_GRAPH" \
        --update-members $(( N_LEARNED * N_SEEDS )) --update-modes "$UPDATE_MODES" | tee "$OUT/bench.jsonl" || status=1
      # Each line names its preset; the budget reads the line of $EXPERIMENT.
      for preset in $RATE_PRESETS; do
        bounded $(( bench_end - $(date +%s) )) "$PY" -m hgm_repro.bench --device "$DEVICE" --only rate \
          "${sizes[@]}" --preset "$preset" --rate-members "$N_SEEDS" \
          --rate-overrides "runtime.cuda_graph=$CUDA_GRAPH" | tee -a "$OUT/bench.jsonl" || status=1
      done
      ;;
    references)
      # At most REFERENCES_S (a third of the time left): cells it leaves are missing from the
      # report, while the learned models keep their time. Its seconds per finished cell size the
      # grid's test cells.
      begin=$(date +%s)
      sweep "${REFERENCES_S:-$(( ($(left) - RESERVE_S) / 3 ))}" "$REFERENCES" | tee "$RUNS/references.log" || status=1
      echo "$(( $(date +%s) - begin )) $(grep -c "job end: " "$RUNS/references.log" || true)" > "$RUNS/references_s"
      ;;
    grid)
      budget=()
      if [ -n "${TOTAL_STEPS:-}" ]; then
        budget=("learner.total_steps=$TOTAL_STEPS")
        echo "training budget: TOTAL_STEPS=$TOTAL_STEPS (given)"
      else
        measured=()
        if [ -f "$RUNS/references_s" ]; then
          read -r seconds cells < "$RUNS/references_s"
          if [ "$cells" -gt 0 ]; then measured=(--reference-seconds "$seconds" --reference-cells "$cells"); fi
        fi
        # The rule itself is scripts/gpu/budget.py; 30 s of the reserve go to the sweep's own start.
        read -r -a budget < <("$PY" scripts/gpu/budget.py --bench "$OUT/bench.jsonl" --seconds-left "$(left)" \
          --preset "$EXPERIMENT" --device "$DEVICE" --groups "$N_LEARNED" \
          --test-cells $(( N_LEARNED * N_SEEDS * N_SCENARIOS )) "${measured[@]}" --reserve $(( RESERVE_S + 30 )) --json "$OUT/budget.json") || true
      fi
      if [ ${#budget[@]} -eq 0 ]; then
        echo "no training budget (scripts/gpu/budget.py failed): the grid is not run" >&2; status=1; continue
      fi
      # Each model's seeds train as one group; no validation passes (the paper tests final.pt).
      sweep "$(left)" "$LEARNED" runtime.grouped=true "runtime.cuda_graph=$CUDA_GRAPH" eval.val_every=0 \
        eval.checkpoint=final "${budget[@]}" \
        | tee "$RUNS/grid.log" || status=1
      # What the trainings reached (a cut-off one stops short of the budget):
      grep -o "grouped training '[a-z_]*': [0-9]*/[0-9]* env steps per member" "$RUNS/grid.log" \
        | awk '{last[$3] = $0} END {for (m in last) print "reached: " last[m]}' || true
      ;;
    collect)
      rm -rf "$RUNS/bundle"
      (cd "$RUNS" && bounded "$(left)" "$PY" -m analysis --write-bundle "$RUNS/bundle" --out "$RUNS/bundle/report") \
        || status=1
      if [ -d "$RUNS/bundle" ]; then
        tar -czf "$OUT/results.tgz" -C "$RUNS" bundle
        if [ -f "$RUNS/bundle/report/report.pdf" ]; then cp "$RUNS/bundle/report/report.pdf" "$OUT/report.pdf"; fi
        echo "results: $OUT/results.tgz (here: tar -xzf results.tgz --strip-components=1 -C docs/results/gpu)"
      fi
      ;;
  esac
done
echo "== done in $(( $(date +%s) - START )) s of LIMIT_S=$LIMIT_S, status $status; in $OUT: $(ls "$OUT" | tr '\n' ' ')"
exec >&- 2>&-
wait "$log_tee" 2>/dev/null || true  # the log's last line is in $OUT before the call returns
exit $status
