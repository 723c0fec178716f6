#!/usr/bin/env bash
# One rung of the scale ladder (experiment=paper_steps or experiment=paper_pixels) trained and tested in
# parts that each fit a session: the sweep runs for MINUTES, then every job is stopped with SIGTERM (each
# writes last.pt and marks its runs KILLED), and what a later session needs to go on is kept in
# research/studies/ladder_state/RUNG/, which is committed: the store's database, its small artifacts and
# each training's checkpoints (a finished training's networks only while small: a paper_pixels training, whose
# last.pt is over 100 MB, must finish and be tested within one session). The replay memory is not kept (runtime.checkpoint_buffer_max_mb=0): a
# resumed training refills it before it learns again, so it is not the run an uninterrupted one would be
# (docs/usage.md, "Interrupting and resuming"). Run the same command in the next session: the state is
# restored into the store (research/studies/runs/ladder/RUNG/, not committed) and the sweep goes on;
# finished trainings and tests are not redone.
#
#   bash research/studies/ladder.sh RUNG MINUTES [Hydra overrides]
#   bash research/studies/ladder.sh paper_pixels 150 model=proposed seed=0,1   # the proposed host's seeds first
#   LADDER_NICE=19 bash research/studies/ladder.sh paper_pixels 150 seed=0      # only on cores left idle
#   bash research/studies/ladder.sh paper_steps keep   # only keep the store's state (a sweep stopped otherwise)
#   bash research/studies/ladder.sh paper_steps extend 15   # the running sweep stops 15 minutes later than set
#
# `extend` is for a training that its rate says ends a few minutes after the stop: the later stop saves a resume
# (a refill of the replay memory) in the next session. The stop is kept in the store (sweep.deadline) while the
# sweep runs.
#
# Without overrides the sweep is the rung's whole row for the proposed host: scenarios 1-5 x seeds 0-4,
# two jobs at once (seed varies fastest, so the first jobs are the trainings). The rung is published
# beside the quick grid with `python -m analysis --bundle docs/results research/studies/runs/ladder/RUNG/bundle
# --write-bundle docs/results --out docs/results/report` after `python -m analysis --write-bundle bundle
# --no-report` in the store; a rung under way is published the same way: its stopped trainings (stopped.csv)
# give the report's scale ladder each one's steps and CPU-hours so far, and the hours left.
set -euo pipefail
if [ "${1:-}" = -h ] || [ "${1:-}" = --help ]; then
  # The help is this header: every comment line from the second to the first line of code.
  sed -n '2,/^[^#]/{/^#/s/^# \{0,1\}//p}' "$0"
  exit 0
fi
cd "$(dirname "$0")/../.."
rung=${1:-}
minutes=${2:-}
case "$rung" in
  paper_steps | paper_pixels) ;;
  *) echo "ladder.sh: rung '${rung}' is not one of: paper_steps paper_pixels" >&2; exit 2 ;;
esac
whole_minutes() { [[ "$1" =~ ^[0-9]+$ ]] && [ "$1" -ge 1 ]; }
if [ "$minutes" = extend ]; then
  more=${3:-}
  if ! whole_minutes "$more"; then
    echo "ladder.sh: extend '${more}' must be a whole number of minutes, at least 1" >&2
    exit 2
  fi
elif [ "$minutes" != keep ] && ! whole_minutes "$minutes"; then
  echo "ladder.sh: MINUTES '${minutes}' must be a whole number of minutes, at least 1 (or 'keep' or 'extend')" >&2
  exit 2
fi
shift 2
ROOT=$PWD
# LADDER_RUNS and LADDER_STATE move the store and the kept state (the script's tests use them).
STORE=${LADDER_RUNS:-$ROOT/research/studies/runs/ladder}/$rung
STATE=${LADDER_STATE:-$ROOT/research/studies/ladder_state}/$rung
# The running sweep's process group and the second (since the epoch) it is stopped at.
deadline_file=$STORE/sweep.deadline

if [ "$minutes" = extend ]; then
  read -r group deadline 2>/dev/null <"$deadline_file" || group=
  if [ -z "$group" ] || ! pgrep -g "$group" >/dev/null; then
    echo "ladder.sh: no $rung sweep is running (no live sweep in $deadline_file): nothing to extend" >&2
    exit 2
  fi
  deadline=$((deadline + more * 60))
  # Written whole, then moved in place: the timer never reads half a line.
  echo "$group $deadline" >"$deadline_file.new" && mv "$deadline_file.new" "$deadline_file"
  echo "ladder.sh: the $rung sweep now stops at $(date -u -d "@$deadline" '+%H:%M:%S UTC')," \
    "$(( (deadline - $(date +%s) + 59) / 60 )) minutes from now"
  exit 0
fi
mkdir -p "$STORE"

# Restore: a store that is not here (a new machine, a new session) starts from the committed state.
if [ -d "$STATE" ] && [ ! -f "$STORE/mlflow.db" ]; then
  cp -a "$STATE/mlflow.db" "$STORE/"
  [ -d "$STATE/artifacts" ] && mkdir -p "$STORE/mlartifacts" && cp -a "$STATE/artifacts/." "$STORE/mlartifacts/"
  [ -d "$STATE/trainings" ] && mkdir -p "$STORE/checkpoints" && cp -a "$STATE/trainings/." "$STORE/checkpoints/"
  echo "ladder.sh: restored $rung from $STATE"
fi

# Keep: first close as KILLED every run the stopped jobs left RUNNING (a job killed before it could close its
# runs, the sweep's own run), as the next launch would; then the database, artifacts under 2 MB but the networks
# (configs, episode tables, records), every training's checkpoints (the replay memory is not in them).
keep() {
  python - "$STORE" <<'PY'
import sys
from pathlib import Path

from hgm_repro.app.store import Tracker, resolve_location

for run_id in Tracker(resolve_location({}, Path(sys.argv[1])), "hgm_repro").close_orphans():
    print(f"ladder.sh: run {run_id} was left RUNNING by a stopped job: marked KILLED")
PY
  rm -rf "$STATE.new"
  mkdir -p "$STATE.new/artifacts" "$STATE.new/trainings"
  sqlite3 mlflow.db ".backup '$STATE.new/mlflow.db'" 2>/dev/null || cp mlflow.db "$STATE.new/mlflow.db"
  # find and cp, not rsync: a fresh machine may not have it.
  if [ -d mlartifacts ]; then
    (cd mlartifacts && find . -type f -size -2049k ! -name '*.pt' ! -name '*.pth' ! -name '*.gif' \
      -exec cp -p --parents {} "$STATE.new/artifacts/" \;)
  fi
  # A finished training's networks only while small: the paper's image size makes them tens of MB, and a job
  # whose test is done needs none (`tested_training`); a test not yet run then trains the key again.
  if [ -d checkpoints ]; then
    for dir in checkpoints/*/; do
      name=$(basename "$dir")
      networks_mb=$(find "$dir" -type f -name '*.pt' -printf '%s\n' | awk '{s += $1} END {print int(s / 1048576)}')
      kept=( -name mlflow_run_id -o -name '*.json' -o -name '*.pt' )
      if [ -f "$dir/final.pt" ] && [ "$networks_mb" -gt "${LADDER_MAX_NETWORK_MB:-20}" ]; then
        kept=( -name mlflow_run_id -o -name '*.json' )
        echo "ladder.sh: the finished training $name's networks (${networks_mb} MB) are not kept: its tests are in" \
          "the store; a test not yet run trains it again"
      fi
      (cd checkpoints && find "$name" -type f \( "${kept[@]}" \) -exec cp -p --parents {} "$STATE.new/trainings/" \;)
    done
  fi
  rm -rf "$STATE"
  mv "$STATE.new" "$STATE"
  size_mb=$(du -sm "$STATE" | cut -f1)
  # What git hosts refuse is one large file (a warning at 50 MB, a refusal at 100 MB), not many small ones: a
  # paper-sized network's last.pt (weights, target, Adam's moments) is over 100 MB, five finished trainings'
  # networks at 36x36 are 9 MB each. The file's apparent size counts (a sparse file is pushed whole).
  largest=$(find "$STATE" -type f -printf '%s %p\n' | sort -n | tail -n 1)
  largest=${largest:-0 (no file)}
  largest_mb=$(( ${largest%% *} / 1048576 ))
  if [ "$largest_mb" -gt "${LADDER_MAX_FILE_MB:-50}" ]; then
    echo "ladder.sh: ${largest#* } is ${largest_mb} MB, more than LADDER_MAX_FILE_MB=${LADDER_MAX_FILE_MB:-50}:" \
      "too large to commit; carry it another way (or train this rung where it fits one session)" >&2
  else
    echo "ladder.sh: commit $STATE (${size_mb} MB) to carry the rung to the next session"
  fi
}

cd "$STORE"
if [ "$minutes" = keep ]; then
  [ -f mlflow.db ] || { echo "ladder.sh: no store at $STORE to keep" >&2; exit 2; }
  keep
  exit 0
fi
log="sweep-$(date -u +%Y%m%dT%H%M%S).log"
# Its own process group, so that the stop reaches the joblib workers too.
setsid python -m hgm_repro -m "experiment=$rung" "scenario='1','2','3','4','5'" model=proposed seed=0,1,2,3,4 \
  launcher=joblib runtime.checkpoint_buffer_max_mb=0 "$@" >"$log" 2>&1 &
sweep=$!
# LADDER_NICE=19: the rung takes only what other work leaves idle. Its own session is its own scheduler
# autogroup, where `nice` alone would not yield to other sessions: the group's nice is what counts.
if [ -n "${LADDER_NICE:-}" ]; then
  # setsid gives the sweep its own session, and so its own autogroup, only once it runs: until then the sweep
  # is in this script's autogroup, and the write would lower the caller's priority instead of the sweep's.
  for _ in $(seq 100); do
    [ "$(ps -o sid= -p "$sweep" | tr -d ' ')" = "$sweep" ] && break
    sleep 0.1
  done
  if [ "$(ps -o sid= -p "$sweep" | tr -d ' ')" != "$sweep" ]; then
    echo "ladder.sh: the sweep has no session of its own yet; its priority is left as it is" >&2
  else
    echo "$LADDER_NICE" >"/proc/$sweep/autogroup" 2>/dev/null ||
      echo "ladder.sh: could not lower the sweep's priority (no /proc/$sweep/autogroup); it runs at full share" >&2
  fi
fi
started=$(date +%s)
echo "$sweep $((started + minutes * 60))" >"$deadline_file"
# The timer sleeps MINUTES, then as long as `extend` has moved the stop, then stops the sweep. A sleep ended by
# the script (the sweep ended first) ends the timer with it.
(
  sleep $((minutes * 60)) || exit 0
  while left=$(( $(cut -d ' ' -f 2 "$deadline_file") - $(date +%s) )); [ "$left" -gt 0 ]; do
    sleep "$left" || exit 0
  done
  kill -TERM -- "-$sweep"
) 2>/dev/null &
timer=$!
status=0
wait "$sweep" || status=$?
ended=$(date +%s)
# A sweep that ends first stops its timer: the sleep first (killing only the subshell would orphan it for the
# rest of MINUTES), which ends the subshell before its kill.
pkill -P "$timer" 2>/dev/null || true
kill "$timer" 2>/dev/null || true
# The sweep's parent exits at once, but its joblib workers go on to write last.pt and mark their runs KILLED,
# and then idle on, orphaned: keep nothing until the group has used no CPU for 15 s, then end what is left.
used=-1
while pgrep -g "$sweep" >/dev/null; do
  now=$(ps -o times= -g "$sweep" | awk '{s += $1} END {print s + 0}')
  [ "$now" = "$used" ] && break
  used=$now
  sleep 15
done
kill -KILL -- "-$sweep" 2>/dev/null || true
rm -f "$deadline_file"
echo "ladder.sh: the sweep ended with status $status after $(( (ended - started + 30) / 60 )) minutes" \
  "(log: $STORE/$log)"

keep
