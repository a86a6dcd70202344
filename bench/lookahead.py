#!/usr/bin/env python3
"""What fetching each sample one pass ahead buys: the sample loop with the
kernel's LOOKAHEAD (as Parallax renders pools of float voxels read with the
2D table) against the same kernel with it made false, in alternating rounds
of fresh processes, on the views of the VTK comparison.

    python3 bench/lookahead.py [--rounds 3] [--csv bench/lookahead.csv]

Needs what `bash bench/vtk_compare.sh` leaves in out/bench-vtk (the
databases and each case's reference render) and a release build. Each
setting's kernel is dumped with PARALLAX_KERNEL_DUMP, the plain loop is
written from it (bench/kernel_variants.py's PLAIN_LOOP) and loaded with
PARALLAX_KERNEL_SOURCE. Both images of a setting must be the same bit for
bit; the script stops if they are not.

Settings: full-precision (float) bricks with the 2D table, where Parallax
uses the lookahead, at the comparison's coarse partners and at finer steps.
Without the 2D table, and on 8-bit bricks, Parallax renders without it (the
runs that chose so are in docs/figures.md, "The next sample one pass
ahead").
"""
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import kernel_variants as kv  # noqa: E402
import vtk_compare as vc  # noqa: E402

# (case, database, step in voxels); all with the 2D table
SETTINGS = [
    ("colin27-brain", "colin27-full-b64", 5.0),
    ("colin27-brain", "colin27-full", 1.5),
    ("colin27-brain", "colin27-full", 0.5),
    ("colin27-skin", "colin27-full", 0.5),
    ("ct-bone", "ct256-full-b64", 8.0),
    ("ct-bone", "ct256-full-b64", 2.0),
    ("ct-bone", "ct256-full", 0.5),
]


def main():
    a, out, px = kv.rounds_arguments(__doc__, "lookahead.csv")
    cases = {c["name"]: c for c in vc.CASES}

    def render(step):
        return dict(step_factor=step, early_termination=vc.VTK_EARLY_TERMINATION, preintegration="2d")

    runs = []
    for i, (case, db, step) in enumerate(SETTINGS):
        dbp = out / f"{db}.pxo"
        ref = out / f"{case}-reference.npy"
        if not dbp.exists() or not ref.exists():
            sys.exit(f"{dbp} or {ref} missing: run bash bench/vtk_compare.sh first")
        base = vc.case_scene(cases[case])
        kdir = out / "lookahead" / f"setting{i}"
        src = kv.dump_kernel(px, kdir, base, dbp, render(step))
        plain = kv.write_variant(kdir, "plain-loop", src, kv.PLAIN_LOOP)
        runs.append(dict(case=case, db=db, step=step, base=base, dbp=dbp,
                         ref=vc.np.load(ref), plain=plain, times={"lookahead": [], "plain": []}))

    for r in range(1, a.rounds + 1):
        vc.log(f"round {r} of {a.rounds}")
        for i, s in enumerate(runs):
            imgs = {}
            for kind in ["lookahead", "plain"]:
                if kind == "plain":
                    os.environ["PARALLAX_KERNEL_SOURCE"] = str(s["plain"])
                img, st = vc.run_parallax(px, f"la{i}-{kind}", s["base"], s["dbp"],
                                          render(s["step"]), out, a.frames, False)
                os.environ.pop("PARALLAX_KERNEL_SOURCE", None)
                s["times"][kind].append(st["render_ms"])
                imgs[kind] = img
            same = vc.np.array_equal(imgs["lookahead"].view(vc.np.uint32), imgs["plain"].view(vc.np.uint32))
            if not same:
                sys.exit(f"{s['case']} {s['db']} step {s['step']}: the images differ")
            s["rmse"] = vc.image_error(imgs["lookahead"], s["ref"])[0]

    rows = []
    vc.log(f"\n{'case':14s} {'bricks':18s} {'step':>5s} {'RMSE':>10s} "
           f"{'lookahead':>9s} {'plain':>7s} {'ratio':>6s}  (runs, ms)")
    for s in runs:
        la, pl = (statistics.median(s["times"][k]) for k in ["lookahead", "plain"])
        row = dict(case=s["case"], database=s["db"], step=s["step"],
                   rmse=f"{s['rmse']:.4e}", lookahead_ms=round(la, 2), plain_ms=round(pl, 2),
                   ratio=round(la / pl, 3),
                   lookahead_runs=" ".join(f"{t:.1f}" for t in s["times"]["lookahead"]),
                   plain_runs=" ".join(f"{t:.1f}" for t in s["times"]["plain"]))
        rows.append(row)
        vc.log(f"{s['case']:14s} {s['db']:18s} {s['step']:5g} {row['rmse']:>10s} "
               f"{la:9.1f} {pl:7.1f} {la / pl:6.3f}  ({row['lookahead_runs']} | {row['plain_runs']})")
    kv.write_csv(a.csv, rows)
    vc.log(f"written: {a.csv} (each pair of images the same bit for bit)")


if __name__ == "__main__":
    main()
