"""What the scripts that time rounds of Parallax runs share (settings_rounds.py):
their options, their CSV and their table."""

import argparse
import csv
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import vtk_compare as vc  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def rounds_arguments(doc, csv_name, extra=None):
    """The options of a script timing rounds of Parallax runs (and those
    `extra` adds to the parser): the arguments, the output folder and the
    binary."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    if extra:
        extra(ap)
    ap.add_argument("--parallax", default=str(ROOT / "target/release/parallax"))
    ap.add_argument("--out", default=str(ROOT / "out/bench-vtk"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--quiet", type=float, default=3.0, help="seconds of quiet before each timed run")
    ap.add_argument("--csv", default=str(vc.BENCH / csv_name) if csv_name else None)
    a = ap.parse_args()
    vc.common.QUIET_S = a.quiet
    return a, Path(a.out).resolve(), str(Path(a.parallax).resolve())


def write_csv(path, rows):
    """`rows` (dicts with the same keys) as a CSV file at `path`."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def log_rounds(rows, name, ratio, against):
    """The table of a rounds script: each row's `name`, RMSE ("cost only"
    where it has none), median ms, `ratio` to the row named `against`, and
    its runs."""
    w = max(18, *(len(row[name]) for row in rows))
    vc.log(f"\n{name:{w}s} {'RMSE':>10s} {'ms':>7s} {'/ ' + against:>8s}  (runs, ms)")
    for row in rows:
        vc.log(f"{row[name]:{w}s} {row['rmse'] or 'cost only':>10s} {row['render_ms']:7.1f} "
               f"{row[ratio]:8.3f}  ({row['runs_ms']})")
