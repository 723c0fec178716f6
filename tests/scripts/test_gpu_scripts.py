"""The GPU-machine scripts (scripts/gpu/): what they carry, and that bad input stops them at once."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT

PROTOCOL = REPO_ROOT / "scripts" / "gpu" / "protocol.sh"


@pytest.fixture(scope="module")
def wheelhouse():
    spec = importlib.util.spec_from_file_location("wheelhouse", REPO_ROOT / "scripts" / "gpu" / "wheelhouse.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_machine_keeps_its_torch_and_gets_the_rest_of_pyproject(wheelhouse):
    requirements = wheelhouse.runtime_requirements()
    names = {wheelhouse.normalise(re.split(r"[<>=!~ \[;]", r, maxsplit=1)[0]) for r in requirements}
    assert "torch" not in names
    assert {"torchrl", "tensordict", "hydra-core", "omegaconf", "mlflow", "gymnasium"} <= names
    # Pins stay pins: the machine runs the versions the tests here ran.
    assert "torchrl==0.14.1" in requirements


def test_image_list_names_the_torch_stack_and_not_what_we_carry(wheelhouse):
    have = wheelhouse.image_packages()
    assert {"torch", "numpy", "pandas", "pyarrow", "seaborn"} <= have
    assert not {"torchrl", "tensordict", "hydra-core", "omegaconf", "mlflow", "gymnasium"} & have
    assert wheelhouse.normalise("Flask_Cors") == wheelhouse.normalise("flask-cors") == "flask-cors"
    for name in ("torch", "triton", "nvidia-cublas", "cuda-bindings"):
        assert wheelhouse.KEEP_THEIRS.match(name)
    assert not wheelhouse.KEEP_THEIRS.match("torchrl")


def test_wheelhouse_refuses_a_malformed_python_version(wheelhouse, capsys):
    with pytest.raises(SystemExit) as stop:
        wheelhouse.main(["--python-version", "python3", "--dest", "/nonexistent/never-made"])
    assert stop.value.code == 2
    assert "'python3'" in capsys.readouterr().err
    assert not Path("/nonexistent/never-made").exists()


def _protocol(*args: str, tmp_path: Path) -> subprocess.CompletedProcess:
    # SITE and OUT in tmp: a run that got past its checks would install there, never in /tmp/site.
    env = {"PATH": "/usr/bin:/bin", "SITE": str(tmp_path / "site"), "OUT": str(tmp_path / "out"),
           "PYTHON": sys.executable}
    return subprocess.run(["bash", str(PROTOCOL), *args], capture_output=True, text=True, env=env, timeout=60)


def test_protocol_script_parses_and_explains_itself(tmp_path):
    assert subprocess.run(["bash", "-n", str(PROTOCOL)]).returncode == 0
    usage = _protocol(tmp_path=tmp_path)
    assert usage.returncode == 2
    assert "check" in usage.stdout and "collect" in usage.stdout and "LIMIT_S" in usage.stdout


def test_protocol_names_an_unknown_step_before_any_work(tmp_path):
    result = _protocol("check", "trian", tmp_path=tmp_path)
    assert result.returncode == 2
    assert "unknown step 'trian'" in result.stderr and "grid" in result.stderr
    assert not (tmp_path / "site").exists() and not (tmp_path / "out").exists()


# --- the training budget of the one-call protocol (scripts/gpu/budget.py) ---------------------------
@pytest.fixture(scope="module")
def budget():
    spec = importlib.util.spec_from_file_location("budget", REPO_ROOT / "scripts" / "gpu" / "budget.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["budget"] = module  # its dataclass looks its module up there
    spec.loader.exec_module(module)
    yield module
    del sys.modules["budget"]


PAPER = dict(preset_steps=1_000_000, preset_eps_steps=1_000_000, paper_steps=1_000_000, floor=20_000, multiple=16)


def test_budget_is_what_the_measured_rate_fits_after_the_tests_and_the_reserve(budget):
    plan = budget.training_budget(400, 1000.0, groups=3, group_fixed_s=10, test_cells=75, cell_s=1.0,
                                  reserve_s=90, safety=0.8, **PAPER)
    # 400 - 90 - 75 - 3 x 10 = 205 s of training loops, 68.3 s per group at 800 env steps/s.
    assert plan.total_steps == 54_656 and plan.total_steps % 16 == 0
    assert plan.eps_steps == plan.total_steps  # Table 4 anneals over the whole run
    assert plan.fits and plan.fraction_of_paper == pytest.approx(0.0547, abs=1e-4)
    assert plan.training_s + plan.test_s + plan.reserve_s <= plan.seconds_left
    # The step above does not fit: the budget is the largest multiple that does.
    assert 3 * (10 + (plan.total_steps + 16) / 800) + 75 + 90 > 400


def test_budget_never_exceeds_the_preset_and_scales_its_exploration(budget):
    plan = budget.training_budget(1e6, 1e5, groups=3, group_fixed_s=10, test_cells=75, cell_s=1.0, reserve_s=90,
                                  **PAPER)
    assert (plan.total_steps, plan.fraction_of_paper, plan.fits) == (1_000_000, 1.0, True)
    quick = budget.training_budget(130, 100.0, groups=1, group_fixed_s=0, test_cells=0, cell_s=0, reserve_s=0,
                                   safety=1.0, preset_steps=80_000, preset_eps_steps=30_000, paper_steps=1_000_000,
                                   floor=2_000, multiple=8)
    assert quick.total_steps == 13_000 and quick.eps_steps == round(13_000 * 30_000 / 80_000)


def test_budget_trains_the_floor_when_nothing_fits_or_nothing_was_measured(budget):
    late = budget.training_budget(100, 1000.0, groups=3, group_fixed_s=10, test_cells=75, cell_s=1.0, reserve_s=90,
                                  **PAPER)
    assert late.total_steps == 20_000 and not late.fits and "floor" in late.note
    blind = budget.training_budget(400, 0.0, groups=3, group_fixed_s=0, test_cells=75, cell_s=1.0, reserve_s=90,
                                   **PAPER)
    assert blind.total_steps == 20_000 and not blind.fits and "no measured rate" in blind.note
    with pytest.raises(ValueError):
        budget.training_budget(400, 1.0, groups=0, group_fixed_s=0, test_cells=0, cell_s=0, reserve_s=0, **PAPER)


def test_budget_reads_its_rate_and_cell_factor_from_the_bench_lines(budget, tmp_path):
    lines = [{"what": "simulator", "n_envs": 8192, "env_steps_per_s": 900_000.0},
             {"what": "simulator+proposed", "n_envs": 8192, "env_steps_per_s": 300_000.0},
             {"what": "simulator+proposed", "n_envs": 32768, "env_steps_per_s": 600_000.0},
             {"what": "learner training, members (paper preset, end to end)", "member_env_steps_per_s": 812.5,
              "fixed_s": 7.5}]
    path = tmp_path / "bench.jsonl"
    path.write_text("".join(json.dumps(row) + "\n" for row in lines) + '{"what": "grouped upd')  # cut off mid-line
    rows = budget.read_bench(path)
    assert len(rows) == 4 and budget.read_bench(tmp_path / "none.jsonl") == []
    assert budget.rate_line(rows)["member_env_steps_per_s"] == 812.5
    assert budget.learned_cell_factor(rows)[0] == pytest.approx(3.0)
    assert budget.learned_cell_factor(rows[:1])[0] == budget.LEARNED_CELL_FACTOR
    assert budget.rate_line(rows[:3]) is None
    # The bench measures other presets' rates after the grid's: the budget reads its own preset's line.
    other = {"what": "learner training, members (paper_steps preset, end to end)", "preset": "paper_steps",
             "member_env_steps_per_s": 2000.0, "fixed_s": 3.0}
    rows = [*rows[:3], {**lines[3], "preset": "paper"}, other]
    assert budget.rate_line(rows, "paper")["member_env_steps_per_s"] == 812.5
    assert budget.rate_line(rows, "paper_steps")["member_env_steps_per_s"] == 2000.0
    assert budget.rate_line(rows, "quick") is None and budget.rate_line(rows)["preset"] == "paper_steps"


def test_budget_cli_prints_the_overrides_and_logs_its_inputs(budget, tmp_path, capsys):
    bench = tmp_path / "bench.jsonl"
    bench.write_text(json.dumps({"member_env_steps_per_s": 50.0, "fixed_s": 2.0}) + "\n")
    assert budget.main(["--bench", str(bench), "--seconds-left", "300", "--preset", "smoke", "--device", "cpu",
                        "--test-cells", "6", "--reference-seconds", "12", "--reference-cells", "6",
                        "--json", str(tmp_path / "budget.json")]) == 0
    out, err = capsys.readouterr()
    assert out.strip() == "learner.total_steps=256 learner.eps_steps=256"  # smoke's whole budget fits
    assert "of Table 4's 1,000,000" in err
    record = json.loads((tmp_path / "budget.json").read_text())
    assert record["total_steps"] == 256 and record["fraction_of_paper"] == 0.0003 and record["paper_steps"] == 10**6
    assert record["rate_line"]["fixed_s"] == 2.0 and record["reference_seconds"] == 12.0


# --- protocol.sh all: one call, in order, writing to $OUT as it goes --------------------------------
FAKE_PYTHON = r"""#!/bin/bash
echo "$*" >> "$CALLS"
case "$*" in
  *"smoke_training_on_cuda[cuda_graph]"*) if [ -n "$FAIL_GRAPH" ]; then exit 1; fi ;;
  *budget.py*) echo "learner.total_steps=4096 learner.eps_steps=4096" ;;
  *hgm_repro.bench*) echo '{"what": "simulator", "n_envs": 8192, "env_steps_per_s": 1.0}' ;;
  *"-m hgm_repro -m"*) echo "job end: model=... (1.0 s)"; echo "job end: model=... (1.0 s)"
    echo "[HYDRA] grouped training 'min': 2048/4096 env steps per member, 9 steps/s per member" ;;
  *"-m analysis"*) mkdir -p "$RUNS/bundle/report" && echo pdf > "$RUNS/bundle/report/report.pdf" ;;
esac
"""


def _fake_all(tmp_path: Path, *args: str, **env: str) -> tuple[subprocess.CompletedProcess, list[str]]:
    """protocol.sh with a stand-in Python that records its calls: the script's structure, in a second."""
    fake = tmp_path / "python"
    fake.write_text(FAKE_PYTHON)
    fake.chmod(0o755)
    calls = tmp_path / "calls.txt"
    environment = {"PATH": "/usr/bin:/bin", "PYTHON": str(fake), "CALLS": str(calls), "SITE": str(tmp_path / "site"),
                   "OUT": str(tmp_path / "out"), "RUNS": str(tmp_path / "runs"), "DEVICE": "cpu",
                   "EXPERIMENT": "smoke", **env}
    result = subprocess.run(["bash", str(PROTOCOL), *args], capture_output=True, text=True, env=environment,
                            timeout=60)
    return result, calls.read_text().splitlines() if calls.exists() else []


def _index(calls: list[str], *needles: str) -> int:
    return next(i for i, call in enumerate(calls) if all(n in call for n in needles))


def test_all_runs_every_step_in_one_call_and_hands_the_budget_to_the_grid(tmp_path):
    result, calls = _fake_all(tmp_path, "all", "--", "simulator.episode_seconds=5", DEVICE="cuda")
    assert result.returncode == 0, result.stderr + result.stdout
    order = [_index(calls, "- cuda"), _index(calls, "-m pytest", "cpu_and_cuda_agree", "smoke_training_on_cuda[eager]"),
             _index(calls, "-m pytest", "smoke_training_on_cuda[cuda_graph]"),
             _index(calls, "-m hgm_repro.bench", "--device cuda", "--only rate", "--rate-members 5",
                    "--update-members 15", "--preset smoke", "--obs-n-envs 8192,32768",
                    "--rate-overrides runtime.cuda_graph=true", "--update-modes eager,bf16,cuda_graph"),
             _index(calls, "-m hgm_repro.bench", "--only rate", "--preset paper_steps"),
             _index(calls, "-m hgm_repro.bench", "--only rate", "--preset paper_pixels"),
             _index(calls, "-m hgm_repro -m", "model=human,idm_mobil,idm_mobil_limits"),
             _index(calls, "budget.py", "--groups 3", "--test-cells 75", "--reference-cells 2"),
             _index(calls, "-m hgm_repro -m", "model=proposed,min,coordinate", "runtime.grouped=true",
                    "runtime.cuda_graph=true", "learner.total_steps=4096 learner.eps_steps=4096"),
             _index(calls, "-m analysis", "--write-bundle")]
    assert order == sorted(order)
    sweeps = [c for c in calls if "-m hgm_repro -m" in c]
    assert len(sweeps) == 2
    assert all("scenario=1,2,3,4,5" in c and "seed=0,1,2,3,4" in c and "eval.test_envs=256" in c
               and "hydra.launcher.n_jobs=8" in c and c.endswith("simulator.episode_seconds=5") for c in sweeps)
    out = tmp_path / "out"
    files = sorted(p.name for p in out.iterdir())
    assert {"protocol.log", "bench.jsonl", "results.tgz", "report.pdf"} <= set(files) and len(files) <= 8
    log = (out / "protocol.log").read_text()
    assert all(f"== {step} (" in log for step in ("check", "bench", "references", "grid", "collect"))
    assert "reached: grouped training 'min': 2048/4096 env steps per member" in log
    assert '"what": "simulator"' in (out / "bench.jsonl").read_text()


def test_a_failing_cuda_graph_leaves_the_bench_and_the_grid_eager(tmp_path):
    result, calls = _fake_all(tmp_path, "all", DEVICE="cuda", FAIL_GRAPH="1")
    assert result.returncode == 1  # the failure is reported, and the call goes on
    assert "CUDA_GRAPH=false" in result.stdout + result.stderr
    runs = [c for c in calls if "-m hgm_repro.bench" in c or "model=proposed,min,coordinate" in c]
    assert len(runs) == 4 and all("runtime.cuda_graph=false" in c for c in runs)
    assert (tmp_path / "out" / "results.tgz").exists()


def test_the_cpu_rehearsal_runs_the_same_steps_on_a_smaller_grid(tmp_path):
    result, calls = _fake_all(tmp_path, "all")
    assert result.returncode == 0, result.stderr + result.stdout
    assert not any("-m pytest" in c for c in calls)  # the CUDA-vs-CPU test needs CUDA
    benches = [c for c in calls if "-m hgm_repro.bench" in c]
    assert len(benches) == 1 and "runtime.cuda_graph=false" in benches[0] and "--update-modes eager" in benches[0]
    assert _index(calls, "budget.py", "--device cpu", "--test-cells 12")
    sweeps = [c for c in calls if "-m hgm_repro -m" in c]
    assert len(sweeps) == 2 and all("seed=0,1 " in c and "scenario=1,2 " in c and "eval.test_envs=4" in c
                                    for c in sweeps)


def test_a_given_budget_skips_the_rule(tmp_path):
    result, calls = _fake_all(tmp_path, "grid", TOTAL_STEPS="2048")
    assert result.returncode == 0, result.stderr
    assert not any("budget.py" in c for c in calls)
    assert any("model=proposed,min,coordinate" in c and "learner.total_steps=2048" in c for c in calls)


def test_near_its_limit_the_call_skips_the_sweeps_but_still_collects(tmp_path):
    # 60 s reserved for collect leaves no time for a sweep in a 70 s call.
    result, calls = _fake_all(tmp_path, "references", "collect", LIMIT_S="70")
    assert result.returncode == 1
    assert not any("-m hgm_repro -m" in c for c in calls) and any("-m analysis" in c for c in calls)
    assert "time limit reached before" in (tmp_path / "out" / "protocol.log").read_text()
    assert (tmp_path / "out" / "results.tgz").is_file()


@pytest.mark.slow  # the whole call on a CPU: up to LIMIT_S (540 s)
def test_cpu_rehearsal_of_all_finishes_within_its_limit_and_its_bundle_builds_a_report(tmp_path):
    import tarfile
    import time

    environment = {"PATH": f"{Path(sys.executable).parent}:/usr/bin:/bin", "PYTHON": sys.executable,
                   "SITE": str(tmp_path / "site"), "OUT": str(tmp_path / "out"), "RUNS": str(tmp_path / "runs"),
                   "DEVICE": "cpu", "EXPERIMENT": "smoke", "HOME": str(tmp_path)}
    start = time.monotonic()
    result = subprocess.run(["bash", str(PROTOCOL), "all"], capture_output=True, text=True, env=environment,
                            timeout=700)
    assert time.monotonic() - start <= 540 + 15  # the limit, and the shell's own start and end
    out = tmp_path / "out"
    assert result.returncode == 0, (out / "protocol.log").read_text()[-3000:]
    files = {p.name for p in out.iterdir()}
    assert {"protocol.log", "bench.jsonl", "budget.json", "results.tgz", "report.pdf"} <= files
    assert json.loads((out / "budget.json").read_text())["total_steps"] > 0
    with tarfile.open(out / "results.tgz") as archive:
        archive.extractall(tmp_path / "unpacked", filter="data")
    report = subprocess.run([sys.executable, "-m", "analysis", "--bundle", str(tmp_path / "unpacked" / "bundle"),
                             "--out", str(tmp_path / "report"), "--no-pictures"], capture_output=True, text=True,
                            cwd=REPO_ROOT, timeout=300)
    assert report.returncode == 0, report.stderr[-2000:]
    assert (tmp_path / "report" / "report.pdf").is_file()
