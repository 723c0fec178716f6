"""What a newcomer sees in the MLflow UI, checked in a real (headless) browser.

Serves a launch directory's store with `mlflow ui`, opens the two links every sweep logs in
Debian's Chromium, and checks the rendered page:

- the evaluations view (`viewStateShareKey=grid`): every evaluation run is a row of the runs
  table, and its model, scenario, seed, episode return and collisions are cells of that row;
- the chart view (`compareRunsMode=CHART&viewStateShareKey=curves`): the first chart section is
  the training curves (`train/`), and no per-cell summary charts come before it.

    python scripts/mlflow_ui_check.py DIR [--screenshot docs/img/mlflow_grid.png]

DIR is where `python -m hgm_repro -m ...` ran (it holds mlflow.db and mlartifacts/). Needs
`chromium` on the PATH (Debian: `apt-get install chromium`). Exit code 0 when both views pass.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from html.parser import HTMLParser
from pathlib import Path

# Without the networking flags Chromium keeps calling Google's hosts, which a closed network refuses.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")
GRID_COLUMNS = {"model": "tags.`model`", "scenario": "tags.`scenario`", "seed": "tags.`seed`",
                "episode return": "metrics.`eval/episode_return`", "collisions": "metrics.`eval/collisions`"}


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_healthy(url: str, server: subprocess.Popen, timeout: float, poll_s: float = 0.5) -> bool:
    """True once an MLflow server at `url` answers /health; False if it exited or `timeout` s passed."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(f"{url}/health", timeout=5) as answer:
                if answer.status == 200:
                    return True
        except OSError:
            pass
        if server.poll() is not None or time.monotonic() > deadline:
            return False
        time.sleep(poll_s)


@contextmanager
def served(launch_dir: Path, timeout: float = 90.0) -> Iterator[str]:
    """`mlflow ui` on the launch directory's store, on a free port; yields its base address."""
    launch_dir = Path(launch_dir).resolve()
    port = free_port()
    command = [sys.executable, "-m", "mlflow", "ui", "--port", str(port), "--host", "127.0.0.1",
               "--backend-store-uri", f"sqlite:///{launch_dir / 'mlflow.db'}",
               "--default-artifact-root", (launch_dir / "mlartifacts").as_uri()]
    log = tempfile.TemporaryFile()
    server = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    base = f"http://127.0.0.1:{port}"
    try:
        if not wait_healthy(base, server, timeout):
            log.seek(0)
            raise RuntimeError(f"mlflow ui did not start: {log.read().decode()[-2000:]}")
        yield base
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()


def _browse(url: str, *args: str, size: str = "1920,1000", budget_ms: int = 20000) -> str:
    """Chromium's output for `url` after `budget_ms` of page time, in a new, empty profile (what a
    newcomer's browser remembers: nothing)."""
    browser = chromium()
    if browser is None:
        raise RuntimeError("no chromium on the PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory() as profile:
        done = subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={size}",
                               f"--virtual-time-budget={budget_ms}", *args, url],
                              capture_output=True, text=True, timeout=180)
    if done.returncode != 0:
        raise RuntimeError(f"chromium failed ({done.returncode}): {done.stderr[-1000:]}")
    return done.stdout


def rendered_dom(url: str) -> str:
    # Wide, so that the table's column virtualisation renders every column.
    return _browse(url, "--dump-dom", size="2400,1400")


def screenshot(url: str, path: Path) -> Path:
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    _browse(url, f"--screenshot={path}")
    return path


class _Rows(HTMLParser):
    """The runs table's cells: {row id (the run id): {column id: text}} from the rendered grid."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: dict[str, dict[str, str]] = {}
        self._stack: list[tuple[str | None, str | None]] = []  # (row id, column id) per open element

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        found = dict(attrs)
        row, column = self._stack[-1] if self._stack else (None, None)
        if "row-id" in found and "ag-row" in (found.get("class") or ""):
            row = found["row-id"]
        if row is not None and "col-id" in found and "ag-cell" in (found.get("class") or ""):
            column = found["col-id"]
        if tag not in ("br", "img", "input", "meta", "link", "hr"):
            self._stack.append((row, column))

    def handle_endtag(self, tag: str) -> None:
        if self._stack:
            self._stack.pop()

    def handle_data(self, data: str) -> None:
        if self._stack and self._stack[-1][0] and self._stack[-1][1] and data.strip():
            cells = self.rows.setdefault(self._stack[-1][0], {})
            column = self._stack[-1][1]
            cells[column] = (cells.get(column, "") + " " + data.strip()).strip()


def table_rows(dom: str) -> dict[str, dict[str, str]]:
    parser = _Rows()
    parser.feed(dom)
    return parser.rows


def _same_number(shown: str, value: float) -> bool:
    try:
        return abs(float(shown.replace(",", "")) - value) <= 1e-3 * max(1.0, abs(value))
    except ValueError:
        return False


def _store(launch_dir: Path):
    from mlflow import MlflowClient

    client = MlflowClient(f"sqlite:///{Path(launch_dir).resolve() / 'mlflow.db'}")
    return client, client.get_experiment_by_name("hgm_repro").experiment_id


def grid_url(launch_dir: Path, base: str) -> str:
    """The link every job logs: the evaluations view."""
    _, experiment_id = _store(launch_dir)
    return f"{base}/#/experiments/{experiment_id}/runs?workflowType=machine_learning&viewStateShareKey=grid"


def curves_url(launch_dir: Path, base: str) -> str:
    """The other link every job logs: the chart view of the training runs."""
    _, experiment_id = _store(launch_dir)
    return (f"{base}/#/experiments/{experiment_id}/runs?workflowType=machine_learning"
            "&compareRunsMode=CHART&viewStateShareKey=curves")


def check_grid(launch_dir: Path, base: str) -> list[str]:
    """Problems with the evaluations view: an evaluation without a row, or a cell missing or wrong."""
    client, experiment_id = _store(launch_dir)
    evaluations = client.search_runs([experiment_id], "tags.stage = 'eval'")
    rows = table_rows(rendered_dom(grid_url(launch_dir, base)))
    problems = [] if evaluations else ["the store holds no evaluation runs"]
    for run in evaluations:
        cells = rows.get(run.info.run_id)
        if cells is None:
            problems.append(f"evaluation {run.info.run_name} ({run.info.run_id}) is not a row of the runs table")
            continue
        tags, metrics = run.data.tags, run.data.metrics
        expected = {"model": tags.get("model"), "scenario": tags.get("scenario"), "seed": tags.get("seed"),
                    "episode return": metrics.get("eval/episode_return"), "collisions": metrics.get("eval/collisions")}
        for what, column in GRID_COLUMNS.items():
            shown, wanted = cells.get(column), expected[what]
            ok = shown is not None and (_same_number(shown, wanted) if isinstance(wanted, float) else shown == wanted)
            if not ok:
                problems.append(f"{run.info.run_name}: {what} shows {shown!r}, the run has {wanted!r}")
    return problems


def check_curves(launch_dir: Path, base: str) -> list[str]:
    """Problems with the chart view: it must open on the training curves."""
    text = re.sub(r"<[^>]+>", " ", rendered_dom(curves_url(launch_dir, base)))
    sections = re.findall(r"\b(train|val|eval|grid|system|Model metrics)\s*\(\d+\)", text)
    if not sections:
        return ["the chart view shows no chart section"]
    if sections[0] != "train":
        return [f"the chart view opens on the section {sections[0]!r}, not on the training curves ({sections})"]
    return []


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("launch_dir", type=Path, help="where the sweep ran: holds mlflow.db and mlartifacts/")
    parser.add_argument("--screenshot", type=Path, default=None, help="also save the evaluations view as a PNG")
    args = parser.parse_args(argv)
    if not (args.launch_dir / "mlflow.db").is_file():
        print(f"mlflow_ui_check: no mlflow.db in {args.launch_dir}", file=sys.stderr)
        return 2
    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
    with served(args.launch_dir) as base:
        problems = check_grid(args.launch_dir, base) + check_curves(args.launch_dir, base)
        if args.screenshot is not None:
            path = screenshot(grid_url(args.launch_dir, base), args.screenshot)
            print(f"screenshot: {path}")
    for problem in problems:
        print(f"mlflow_ui_check: {problem}", file=sys.stderr)
    print("mlflow_ui_check: " + ("FAILED" if problems else "every evaluation is a readable row; the chart view "
                                 "opens on the training curves"))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
