"""The GPU-machine scripts (scripts/gpu/): what they carry, and that bad input stops them at once."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "scripts" / "gpu" / "protocol.sh"


@pytest.fixture(scope="module")
def wheelhouse():
    spec = importlib.util.spec_from_file_location("wheelhouse", ROOT / "scripts" / "gpu" / "wheelhouse.py")
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
