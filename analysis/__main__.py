"""`python -m analysis`: read the MLflow store, write figures, tables and reports/report.pdf."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from analysis.load import EmptyStoreError, default_tracking_uri, load_store


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m analysis",
        description="Build the reproduction report from the MLflow tracking store: training curves "
                    "(paper Figs. 5-7), the test table (Table 6) with 95% bootstrap CIs over seeds, "
                    "verdicts on the paper's seven claims, and reports/report.pdf.",
        epilog="Example: python -m analysis --tracking-uri sqlite:////abs/path/mlflow.db --out reports/",
    )
    parser.add_argument("--tracking-uri", default=None,
                        help="MLflow tracking URI (default: sqlite file mlflow.db in the current directory, "
                             "the same store `python -m hgm_repro` writes to)")
    parser.add_argument("--experiment", default="hgm_repro", help="MLflow experiment name (default: hgm_repro)")
    parser.add_argument("--out", type=Path, default=Path("reports"),
                        help="directory for report.pdf, figures (PNG/PDF/SVG) and CSV tables (default: reports/)")
    parser.add_argument("--no-pictures", action="store_true",
                        help="skip the camera/HGM pictures (they run the simulator for a few steps)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    uri = args.tracking_uri or default_tracking_uri()
    try:
        data = load_store(uri, args.experiment)
    except EmptyStoreError as exc:
        print(f"analysis: nothing to report: {exc}", file=sys.stderr)
        return 1
    from analysis.pipeline import build_outputs  # heavy imports (matplotlib, fpdf) only when there is data

    outputs = build_outputs(data, args.out, pictures=not args.no_pictures)
    print(f"report: {outputs.report}")
    for name, paths in outputs.figures.items():
        print(f"figure {name}: {', '.join(str(p) for p in paths.values())}")
    for path in outputs.csvs:
        print(f"table: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
