"""`python -m analysis`: read the MLflow store (or a results bundle), write figures, tables and reports/report.pdf."""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

from analysis.bundle import BundleError, describe, load_bundle, write_bundle
from analysis.combine import combine
from analysis.load import EmptyStoreError, StoreData, default_tracking_uri, load_store


def _files_text() -> str:
    # Raw formatting keeps the layout below, so the file lines are wrapped here.
    return "\n".join(textwrap.fill(line, width=96, initial_indent="    ", subsequent_indent="      ")
                     for line in describe().splitlines())


BUNDLE_HELP = f"""\
results bundle:
  A bundle holds everything the report reads from a store, as small CSV files, so that results
  travel (and can be committed, as docs/results/ is) without the store and its checkpoints. The
  report built from a bundle equals the one built from its store. Files:
{_files_text()}

examples:
  python -m analysis                                        # ./mlflow.db -> reports/
  python -m analysis --tracking-uri sqlite:////abs/path/mlflow.db --out reports/
  python -m analysis --write-bundle results/ --no-report    # store -> bundle only
  python -m analysis --write-bundle results/                # store -> bundle and reports/
  python -m analysis --bundle results/ --out reports/       # bundle -> reports/, no store needed
  python -m analysis --bundle results/ variant/ --write-bundle results/   # a variant's bundle into the grid's
"""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m analysis",
        description=textwrap.fill(
            "Build the reproduction report from the MLflow tracking store or from a results bundle: training "
            "curves (paper Figs. 5-7), the test table (Table 6) with 95% bootstrap CIs over seeds, verdicts on "
            "the paper's seven claims, reports/report.pdf, and reports/results.md (Table 6 beside the paper's, "
            "collisions, speed and the claims in Markdown, for a README).", width=96),
        epilog=BUNDLE_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--tracking-uri", default=None,
                        help="MLflow tracking URI (default: sqlite file mlflow.db in the current directory, "
                             "the same store `python -m hgm_repro` writes to)")
    source.add_argument("--bundle", type=Path, nargs="+", default=None, metavar="DIR",
                        help="read a results bundle (written by --write-bundle) instead of a store; several "
                             "bundles are read as one (a variant beside the published grid), and a model at an "
                             "experiment preset that a later bundle holds replaces its runs at that preset in the "
                             "earlier ones")
    parser.add_argument("--experiment", default="hgm_repro", help="MLflow experiment name (default: hgm_repro)")
    parser.add_argument("--write-bundle", type=Path, default=None, metavar="DIR",
                        help="also write what was read (store or bundle) as a results bundle into DIR")
    parser.add_argument("--no-report", action="store_true",
                        help="with --write-bundle: write only the bundle, no report, figures or tables")
    parser.add_argument("--out", type=Path, default=Path("reports"),
                        help="directory for report.pdf, results.md, figures (PNG/PDF/SVG) and CSV tables "
                             "(default: reports/)")
    parser.add_argument("--no-pictures", action="store_true",
                        help="skip the camera/HGM pictures (they run the simulator for a few steps)")
    args = parser.parse_args(argv)
    if args.no_report and args.write_bundle is None:
        parser.error("--no-report leaves nothing to do without --write-bundle DIR")
    return args


def _read(args: argparse.Namespace) -> StoreData:
    if args.bundle is not None:
        return combine([load_bundle(directory) for directory in args.bundle])
    return load_store(args.tracking_uri or default_tracking_uri(), args.experiment)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        data = _read(args)
    except (EmptyStoreError, BundleError) as exc:
        print(f"analysis: nothing to report: {exc}", file=sys.stderr)
        return 1
    if args.write_bundle is not None:
        files = write_bundle(data, args.write_bundle)
        print(f"bundle: {args.write_bundle} ({len(files)} files)")
    if args.no_report:
        return 0
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
