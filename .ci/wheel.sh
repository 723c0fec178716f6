#!/usr/bin/env bash
# The install a user without a checkout gets: build the wheel from the working tree's files (tracked
# and untracked-not-ignored, copied away so that no stale build/ output can slip in), install it with
# its dependencies into a fresh venv, and run the CLI, a smoke job and the Gymnasium env from a
# directory outside the checkout, where only the installed package can answer.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
PY=${PYTHON:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

mkdir "$work/src" "$work/dist" "$work/run"
git ls-files -z --cached --others --exclude-standard | while IFS= read -r -d '' f; do
  [ -e "$f" ] && printf '%s\0' "$f"
done | tar --null -cf - -T - | tar -xf - -C "$work/src"

echo "== build the wheel"
"$PY" -m pip wheel -q --no-deps -w "$work/dist" "$work/src"
wheel=$(ls "$work"/dist/hgm_repro-*.whl)
echo "$(basename "$wheel")"

echo "== install it with its dependencies into a fresh venv"
"$PY" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q "$wheel"
if "$work/venv/bin/python" -m pip list 2>/dev/null | grep -qi '^nvidia-'; then
  echo "CUDA wheels were pulled into a CPU install:"; "$work/venv/bin/python" -m pip list | grep -i '^nvidia-'; exit 1
fi
"$work/venv/bin/python" -c "import torch; assert torch.__version__.startswith('2.13.0'), torch.__version__"

echo "== run it from outside the checkout ($work/run)"
cd "$work/run"
export PATH="$work/venv/bin:$PATH"
python -c "import hgm_repro, sys; assert 'site-packages' in hgm_repro.__file__, hgm_repro.__file__; print(hgm_repro.CONF_DIR)"
python -m hgm_repro --cfg job >/dev/null
hgm-repro --help >/dev/null
python -m hgm_repro experiment=smoke
python -c "import gymnasium as gym, hgm_repro; gym.make('hgm_repro/HeterogeneousHighway-v0').reset(seed=0)"
python -c "import gymnasium as gym, hgm_repro
envs = gym.make_vec('hgm_repro/HeterogeneousHighway-v0', num_envs=4, vectorization_mode='vector_entry_point')
envs.reset(seed=0); envs.step(envs.action_space.sample())"
echo "wheel check: $(( $(date +%s) - start )) s"
