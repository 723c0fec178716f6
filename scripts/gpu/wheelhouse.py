"""Wheels for a GPU machine that has its own torch and no network.

The lent GPU machine (Python 3.12, torch 2.11 with CUDA, the packages in `image_packages.txt`)
lacks torchrl, tensordict, hydra, omegaconf, mlflow and a few more, and cannot reach a package
index. Run this where pip can reach one: it resolves the project's runtime dependencies (from
pyproject.toml, torch left out so that the machine keeps its own) for the target Python and
manylinux, at the versions installed here (so the GPU runs the versions the tests ran), drops
what the machine's image already holds, and downloads the rest into one folder:

    python scripts/gpu/wheelhouse.py                 # -> .whl/ (git-ignored), about 50 MiB
    python scripts/gpu/wheelhouse.py --python-version 3.11 --dest /tmp/whl311   # a local rehearsal

`scripts/gpu/protocol.sh` installs that folder on the machine (`pip install --no-deps --target`),
beside its torch rather than over it.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
# pip matches manylinux tags exactly: offer every one a wheel of ours may carry.
PLATFORMS = ("manylinux_2_34_x86_64", "manylinux_2_31_x86_64", "manylinux_2_28_x86_64", "manylinux_2_27_x86_64",
             "manylinux_2_24_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64", "manylinux1_x86_64")
# Never carried: the machine's own torch stack (replacing it would lose its CUDA build).
KEEP_THEIRS = re.compile(r"^(torch|triton|nvidia-.*|cuda-.*)$")
# Published only as source; pure Python, so a wheel built here runs anywhere.
SOURCE_ONLY = ("antlr4-python3-runtime",)
# The whole call carries the source tree too (about 2 MiB) under a 64 MiB limit.
DEFAULT_MAX_MIB = 60.0


def normalise(name: str) -> str:
    """PEP 503 name: 'Flask_Cors' and 'flask-cors' are one package."""
    return re.sub(r"[-_.]+", "-", name).lower()


def runtime_requirements(pyproject: Path = ROOT / "pyproject.toml") -> list[str]:
    """The project's install requirements, torch left out (the machine brings its own)."""
    deps = tomllib.loads(pyproject.read_text())["project"]["dependencies"]
    return [d for d in deps if not KEEP_THEIRS.match(normalise(re.split(r"[<>=!~ \[;]", d, maxsplit=1)[0]))]


def image_packages(path: Path = HERE / "image_packages.txt") -> set[str]:
    """Packages the GPU machine's image already holds (one name per line, # comments)."""
    names = (line.split("#", 1)[0].strip() for line in path.read_text().splitlines())
    return {normalise(n) for n in names if n}


def installed_versions() -> dict[str, str]:
    """name -> version of what this interpreter has installed (the versions the tests ran with)."""
    out = subprocess.run([sys.executable, "-m", "pip", "list", "--format=json", "--disable-pip-version-check"],
                         check=True, capture_output=True, text=True).stdout
    return {normalise(p["name"]): p["version"] for p in json.loads(out)}


def _pip(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "pip", *args, "--disable-pip-version-check", "-q"], check=True)


def _target_flags(python_version: str) -> list[str]:
    flags = ["--python-version", python_version, "--implementation", "cp", "--only-binary=:all:"]
    for platform in PLATFORMS:
        flags += ["--platform", platform]
    return flags


# pip names a pin it cannot meet for the target (no wheel of that version for its Python) this way.
UNMET_PIN = re.compile(r"The user requested \(constraint\) ([A-Za-z0-9_.\-]+)==")


def resolve(requirements: list[str], pins: dict[str, str], python_version: str, find_links: Path) -> dict[str, str]:
    """The full dependency closure for the target interpreter, as name -> version.

    A version installed here that has no wheel for the target Python (an older orjson built for
    3.11 only, say) cannot be pinned there: its pin is dropped, said on stderr, and pip chooses."""
    pins = {n: v for n, v in pins.items() if not KEEP_THEIRS.match(n) and n != "hgm-repro"}
    with tempfile.TemporaryDirectory() as tmp:
        constraints = Path(tmp) / "constraints.txt"
        report = Path(tmp) / "report.json"
        for _ in range(len(pins) + 1):
            constraints.write_text("".join(f"{name}=={version}\n" for name, version in sorted(pins.items())))
            done = subprocess.run([sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed",
                                   "--report", str(report), "--target", str(Path(tmp) / "t"), "--find-links",
                                   str(find_links), "-c", str(constraints), *_target_flags(python_version),
                                   *requirements, "--disable-pip-version-check"],
                                  capture_output=True, text=True)
            if done.returncode == 0:
                break
            unmet = {normalise(n) for n in UNMET_PIN.findall(done.stdout + done.stderr)} & set(pins)
            if not unmet:
                sys.stderr.write(done.stderr)
                raise SystemExit(f"pip could not resolve the requirements for Python {python_version}")
            for name in sorted(unmet):
                print(f"{name}=={pins.pop(name)} has no wheel for Python {python_version} here: not pinned",
                      file=sys.stderr)
        installs = json.loads(report.read_text())["install"]
    return {normalise(i["metadata"]["name"]): i["metadata"]["version"] for i in installs}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dest", type=Path, default=ROOT / ".whl", help="folder for the wheels (default: %(default)s)")
    parser.add_argument("--python-version", default="3.12", help="the GPU machine's Python (default: %(default)s)")
    parser.add_argument("--max-mib", type=float, default=DEFAULT_MAX_MIB,
                        help="fail if the wheels weigh more (default: %(default)s; a device call carries 64 MiB)")
    args = parser.parse_args(argv)
    if not re.fullmatch(r"3\.\d+", args.python_version):
        parser.error(f"--python-version {args.python_version!r}: give major.minor, for example 3.12")
    args.dest.mkdir(parents=True, exist_ok=True)
    for stale in args.dest.glob("*.whl"):
        stale.unlink()  # two versions of one package would stop the install there

    pins = installed_versions()
    for name in SOURCE_ONLY:
        version = pins.get(name)
        _pip("wheel", "--no-deps", "-w", str(args.dest), f"{name}=={version}" if version else name)
    closure = resolve(runtime_requirements(), pins, args.python_version, args.dest)
    have = image_packages()
    carry = {n: v for n, v in closure.items() if n not in have and not KEEP_THEIRS.match(n)}
    wanted = [f"{name}=={version}" for name, version in sorted(carry.items()) if name not in SOURCE_ONLY]
    _pip("download", "--no-deps", "-d", str(args.dest), *_target_flags(args.python_version), *wanted)
    wheels = sorted(args.dest.glob("*.whl"))
    mib = sum(w.stat().st_size for w in wheels) / 2**20
    for wheel in wheels:
        print(f"{wheel.stat().st_size / 2**20:7.2f} MiB  {wheel.name}")
    print(f"{len(wheels)} wheels, {mib:.1f} MiB in {args.dest} (closure {len(closure)} packages, "
          f"{len(closure) - len(carry)} already on the machine or its own torch stack)")
    if mib > args.max_mib:
        print(f"the wheels weigh {mib:.1f} MiB, over --max-mib {args.max_mib}: a device call carries 64 MiB "
              "with the source tree", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
