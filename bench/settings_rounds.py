#!/usr/bin/env python3
"""Error against the reference and render time of any render settings on
one view of the VTK comparison, in alternating rounds of fresh processes:
for trying a knob (bricks, level of detail, step, table) before it goes
into a ladder of bench/vtk_compare.py.

    python3 bench/settings_rounds.py CASE NAME:DATABASE:KEY=VALUE,... [...]
        [--rounds 3] [--csv out/bench-vtk/settings_rounds.csv]

CASE is one of bench/vtk_compare.py's CASES (colin27-brain, colin27-skin,
ct-bone). DATABASE names out/bench-vtk/<stem>-DATABASE.pxo, the stem the
case's volume (colin27 or ct256): full, 8bit, full-b64, 8bit-b64, and
full-b128, 8bit-b128 where they have been imported. KEY=VALUE are [render]
settings laid over the comparison's (early termination at VTK's, the 2D
table), e.g.

    python3 bench/settings_rounds.py colin27-brain \\
        fine:full-b64:step_factor=5.5 coarse:full:step_factor=1.0,accuracy=8.0

Needs what `bash bench/vtk_compare.sh` leaves in out/bench-vtk (the
databases and each case's reference render) and a release build. Each
round runs every setting once (`parallax render --sync`, 16 frames, the
median render_ms of the last 8) after a few quiet seconds; the table gives
each setting's RMSE and the median over the rounds.
"""
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rounds as kv  # noqa: E402
import vtk_compare as vc  # noqa: E402


def value(text):
    """A TOML value from the command line: a bool, a number or a string."""
    if text in ("true", "false"):
        return text == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def setting(spec):
    """NAME:DATABASE:KEY=VALUE,... → (name, database, render overrides)."""
    try:
        name, db, kvs = spec.split(":", 2)
        render = dict(early_termination=vc.VTK_EARLY_TERMINATION, preintegration="2d")
        for item in filter(None, kvs.split(",")):
            k, v = item.split("=", 1)
            render[k.strip()] = value(v.strip())
    except ValueError:
        sys.exit(f"{spec!r}: expected NAME:DATABASE:KEY=VALUE,...")
    return name, db, render


def main():
    def extra(ap):
        ap.add_argument("case", choices=[c["name"] for c in vc.CASES])
        ap.add_argument("settings", nargs="+", help="NAME:DATABASE:KEY=VALUE,...")

    a, out, px = kv.rounds_arguments(__doc__, None, extra)
    csv_path = Path(a.csv) if a.csv else out / "settings_rounds.csv"
    case = next(c for c in vc.CASES if c["name"] == a.case)
    stem = "colin27" if case["volume"] == "colin27" else "ct256"
    ref_path = out / f"{a.case}-reference.npy"
    settings = [setting(s) for s in a.settings]
    if len({n for n, _, _ in settings}) != len(settings):
        sys.exit("every setting needs a name of its own")
    for _, db, _ in settings:
        if not (out / f"{stem}-{db}.pxo").exists():
            sys.exit(f"{out / f'{stem}-{db}.pxo'} missing: run bash bench/vtk_compare.sh (or import it)")
    if not ref_path.exists():
        sys.exit(f"{ref_path} missing: run bash bench/vtk_compare.sh first")
    ref = vc.np.load(ref_path)
    base = vc.case_scene(case)

    times = {n: [] for n, _, _ in settings}
    errors = {}
    for r in range(1, a.rounds + 1):
        vc.log(f"round {r} of {a.rounds}")
        for name, db, render in settings:
            img, st = vc.run_parallax(px, f"sr-{a.case}-{name}", base, out / f"{stem}-{db}.pxo", render,
                                      out, a.frames, False)
            times[name].append(st["render_ms"])
            errors[name] = vc.image_error(img, ref)[0]

    first = settings[0][0]
    med = {n: statistics.median(t) for n, t in times.items()}
    rows = [dict(case=a.case, setting=n, database=db,
                 render=" ".join(f"{k}={v}" for k, v in render.items()),
                 rmse=f"{errors[n]:.4e}", render_ms=round(med[n], 2),
                 runs_ms=" ".join(f"{t:.1f}" for t in times[n]),
                 ratio_to_first=round(med[n] / med[first], 3))
            for n, db, render in settings]
    kv.write_csv(csv_path, rows)
    kv.log_rounds(rows, "setting", "ratio_to_first", "first")
    vc.log(f"written: {csv_path}")


if __name__ == "__main__":
    main()
