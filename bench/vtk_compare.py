#!/usr/bin/env python3
"""Parallax's GPU ray caster (on whatever adapter wgpu picks: lavapipe on the
2-core reference machine) against VTK's CPU ray caster
vtkFixedPointVolumeRayCastMapper, on the same 512×512 view, at matched step
lengths, both measured against one reference image. Four comparisons in one
run (CASES): the Colin27 MRI with a translucent brain (the full study), the
same head as opaque skin, a 256³ CT phantom in Hounsfield units that is
mostly air, under 3D Slicer's CT-Bone preset, and a thick-slice CT (512 ×
512 × 48, 10.7 mm slices) under CT-Soft-Tissue, where Parallax keeps every
default but accuracy and step_factor (issue 40).

What a pixel means (docs/design.md): with shading off, the premultiplied
emission–absorption integral C = ∫ τ c exp(−∫τ) dt, A = 1 − exp(−∫τ dt) along
the pixel's ray inside the box [0, N·s]. Every image here is compared with the
reference as float premultiplied RGBA (RMSE over all channels and pixels, max
abs, PSNR with peak 1), as `parallax bench sweep` does.

The reference is Parallax itself at a very small step (1/16 mm: render.step_factor =
0.25 at accuracy = 0.01, whose sub-pixel step is a quarter of it; interpolation =
"exact", full-precision bricks, early_termination = 1, no visibility culling). `parallax
bench sweep` measures that configuration at RMSE ≈ 3e-5 from the exact integral on
this dataset (out/bench/bench.csv), far below every error compared here.

VTK is set up to compute the same integral: the same camera (inverse scene
placement), colours at every data value, per-unit-distance opacity
α = 1 − exp(−τ·1 mm) with ScalarOpacityUnitDistance 1, trilinear
interpolation, no shading, 2 threads. Its volume is padded with one
replicated voxel and cropped to [0, N·s], because VTK's own domain ends at
the outer voxel centres, half a voxel short of Parallax's box (the "voxel-
centre box" rows show VTK as it comes). Its image is read twice: the
mapper's own 15-bit ray-cast image (the fair comparison) and the 8-bit
window framebuffer (what a VTK user sees). Early termination: VTK stops a
ray at opacity 1 − 255/32768; Parallax is timed with that threshold and
with none.

Parallax is also run with a cheaper pre-integration than the exact table's
five reads, which dominate a sample's cost on lavapipe (the case's
`preint`): the exact integral in closed form (render.preintegration =
"analytic": per segment, a few products per piece of the transfer function
between its control points) for the two Colin27 functions of 4 and 6
points, or the 2D table (render.preintegration = "2d": one bilinear fetch
a segment, what every case used before the closed form) for the CT's 14,
where the closed form's pieces cost more than the fetch;
on a finer ladder of steps (TABLE_STEPS), early termination matched; and the same
from a database imported with bricks of 64 voxels instead of 32 (`parallax
import --brick 64`: half as many leaves along a ray, so less traversal per
ray; the finest level is the same data) on the coarser steps
(BIG_BRICK_STEPS), where that cost weighs most. Both ladders run on
8-bit and on full-precision bricks. A third ladder draws the full-precision bricks
of 64 one level of detail coarser (render.accuracy = 6, opaque_detail = 1: level 1, 2 mm
voxels, on every case's view; COARSE_STEPS). Then, for each VTK setting,
the ladder that holds its partner is bisected twice (REFINE) between its
largest step as accurate as VTK and its next, so that the partner's step
is not set by the ladder's spacing. A single run can pick the wrong one:
the rows that might be a partner (the fastest few as accurate as each
VTK setting, SHORTLIST) are timed twice more in fresh processes, and
the partner is the fastest by the median of its runs (columns runs,
first_ms).

Timing: Parallax's render_ms (median of the last 8 of 16 --sync frames)
against the wall time of renWin.Render() (median of 5 after a warm-up).
The machine is shared: every timed section waits until other processes
have been idle for 10 s and is repeated if they took more than 0.1 core
meanwhile (columns cores / other_cores).

VTK's times move between processes far more than within one (the brain at
4 mm: 55 to 86 ms over three runs on one machine, each run's five renders
within 1 %), and the machine's speed drifts over a run of half an hour. So
after each case, every VTK setting and its equal-error partner are timed
again in alternating pairs (--pairs, default 3; the order alternates,
VTK first in odd pairs), each side in a fresh process (VTK through this
script's --vtk-time mode): the ratio of the two sides' medians over the
pairs, and the spread of the pairs' own ratios, go to the summary and to
bench/vtk_pairs.csv.

Run it through bench/vtk_compare.sh (installs vtk + numpy, imports the two
databases, builds). Outputs go to out/bench-vtk/ (git-ignored) and the table
to bench/vtk_results.csv.
"""

import argparse
import csv
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import NamedTuple

import numpy as np

import bench_common as common
from bench_common import (Meter, Placement, alpha_centroid, best_shift, image_error, load_tf,
                          log, to_srgb8, wait_idle, write_png)
from vtk_side import H, W, read_nrrd, vtk_read_volume, vtk_run, vtk_setup

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT / "bench"
# VTK's fixed-point compositing stops a ray once the remaining transparency
# drops below 0xff in 15-bit fixed point (vtkFixedPointVolumeRayCastHelper.h,
# CompositeColorAndCheckEarlyTermination): opacity 1 − 255/32768.
VTK_EARLY_TERMINATION = 1.0 - 255.0 / 32768.0
STEPS = [0.25, 0.5, 1.0]          # matched steps (mm): ours and VTK
EXTRA_STEPS = [2.0, 4.0]          # coarser, to find equal-error pairs
# The ladders below pre-integrate as the case's `preint` says, early
# termination matched, on a finer ladder of steps so that each VTK setting
# finds its equal-error partner; their labels name it.
PREINT_LABELS = {"analytic": "closed form", "2d": "2D table"}
TABLE_STEPS = [0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0]
BIG_BRICK_STEPS = [1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 5.5, 6.0, 7.0, 8.0]
# One level of detail coarser (2 mm voxels, the full-precision bricks of
# 64): render.accuracy 6 (a voxel may cover up to 6 pixels) with
# render.opaque_detail 1 (opaque voxels held to the same 6) draws every
# case's level 1 on this view, whose level-0 voxels cover 1.7–2.3 pixels.
# Its steps in mm; step_factor counts the level's voxels, half as many.
COARSE_ACCURACY = 6.0
COARSE_VOXEL_MM = 2.0
COARSE_STEPS = [2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0]
# Bisections of the partner's ladder between its rungs, per VTK setting.
REFINE = 2
# The shortlist: per VTK setting, the fastest rows as accurate (at most
# SHORTLIST, within SHORTLIST_MARGIN of the fastest's one run) are timed
# SHORTLIST_RUNS times more, each in a fresh process, in rounds of
# alternating order, and the partner is the fastest by the median of all
# their runs. One run each picked a partner that the pairs then timed
# 16 % slower than the usual one (the brain at 4 mm, 7823daa's run,
# bench/vtk_pairs_xeon_brain2.csv).
SHORTLIST = 3
SHORTLIST_MARGIN = 1.25
SHORTLIST_RUNS = 2


class Ladder(NamedTuple):
    """A ladder of Parallax runs pre-integrated as its case says: the database (a key of
    run_case's `dbs`), its steps in mm, the voxel of the level it draws in
    mm (step_factor = step / voxel_mm), further render settings, and a tag
    for its runs' names."""
    db: str
    steps: list
    voxel_mm: float = 1.0
    render: dict | None = None
    tag: str = ""

STAGES = ["refine_ms", "upload_ms", "index_ms", "render_ms", "output_ms", "total_ms"]


# --------------------------------------------------------------------------
# Parallax runs.

def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return json.dumps(str(v))


def write_scene(path, base, db, render):
    """A variant of bench/vtk_scene.toml with absolute paths."""
    lines = [
        "# written by bench/vtk_compare.py from bench/vtk_scene.toml",
        f"volume = {toml_value(db)}",
        f"transfer_function = {toml_value((BENCH / base['transfer_function']).resolve())}",
        f"display = {toml_value((BENCH / base['display']).resolve())}",
        "",
        "[placement]",
    ]
    lines += [f"{k} = {toml_value(v)}" for k, v in base["placement"].items()]
    lines += ["", "[render]"]
    r = dict(base["render"])
    r.update(render)
    lines += [f"{k} = {toml_value(v)}" for k, v in r.items()]
    text = "\n".join(lines) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return text


def run_parallax(px, name, base, db, render, out, frames, reuse, timed=True):
    scenes = out / "scenes"
    runs = out / "runs"
    scene = scenes / f"{name}.toml"
    text = write_scene(scene, base, db, render)
    rdir = runs / name
    last = rdir / f"frame_{frames - 1:05d}" / "window.npy"
    stamp = rdir / "scene.toml"
    meta = rdir / "meter.json"
    if reuse and last.exists() and stamp.exists() and stamp.read_text() == text and meta.exists():
        log(f"  {name}: reusing {rdir}")
        m = json.loads(meta.read_text())
    else:
        cmd = [str(px), "render", "--scene", str(scene), "--float", "--sync",
               "--frames", str(frames), "--out", str(rdir)]
        log("  $ " + " ".join(os.path.relpath(c, ROOT) if c.startswith("/") else c for c in cmd))
        t_start = time.time()
        for attempt in range(1, 100):
            if rdir.exists():
                shutil.rmtree(rdir)
            if timed:
                wait_idle()
            with Meter(children=True) as mt:
                p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            if p.returncode != 0:
                sys.exit(f"parallax render failed for {name}:\n{p.stdout}\n{p.stderr}")
            m = dict(wall_s=mt.wall, cores=mt.cores, other_cores=mt.other_cores, attempt=attempt)
            log(f"    {frames} frames in {mt.wall:.1f} s, {mt.cores:.2f} cores busy on average, "
                f"other processes {mt.other_cores:.2f} cores")
            if mt.other_cores < 0.1 or not timed:
                break
            if time.time() - t_start > 3600:
                log("    WARNING: no undisturbed run within an hour: keeping this one (see other_cores)")
                break
            log("    (disturbed by other processes: again)")
        (rdir / "log.txt").write_text(p.stdout + p.stderr)
        stamp.write_text(text)
        meta.write_text(json.dumps(m))
    img = np.load(last)
    assert img.shape == (H, W, 4) and img.dtype == np.float32, img.shape
    stats = [json.loads(l) for l in (rdir / "stats.jsonl").read_text().splitlines() if l.strip()]
    stats.sort(key=lambda s: s["frame"])
    tail = stats[-max(3, frames // 2):]
    med = {k: statistics.median(s[k] for s in tail) for k in STAGES}
    med["bricks"] = tail[-1]["cut_leaves_with_data"]
    med["adequate"] = all(s["adequate"] for s in tail)
    med["uploaded_tail"] = sum(s["uploaded"] for s in tail)
    # Frames 0 and 1 have nothing, or only the coarse root brick, resident:
    # the lighter one bounds the fixed per-frame cost (dispatch, image and
    # feedback readback) from above.
    med["light_frame_render_ms"] = min(s["render_ms"] for s in stats[:2])
    med["cores"] = m["cores"]
    med["other_cores"] = m["other_cores"]
    return img, med




# --------------------------------------------------------------------------
# Alternating pairs: each VTK setting against its equal-error partner, both
# in fresh processes, the order alternating.

def vtk_time_main(a):
    """--vtk-time CASE STEP: one VTK set-up (box domain) in this process,
    `repeats` timed renders at STEP; prints a line VTKTIME {json}."""
    case_name, step = a.vtk_time[0], float(a.vtk_time[1])
    case = next(c for c in CASES if c["name"] == case_name)
    out = Path(a.out)
    volume = read_case_volume(case, out)
    base = tomllib.loads((BENCH / "vtk_scene.toml").read_text())
    tf = load_tf((BENCH / case["tf"]).resolve())
    pl = base["placement"]
    extent = tuple(d * s for d, s in zip(volume[1], volume[2]))
    placement = Placement(pl["center"], pl["size"], pl["rotation_deg"], extent)
    v = vtk_setup(tf, placement, a.threads, "box", volume)
    times, cores, other, fb, rc = vtk_run(v, step, a.repeats)
    ref = out / f"{case_name}-reference.npy"
    rmse = image_error(rc, np.load(ref))[0] if ref.exists() else None
    print("VTKTIME " + json.dumps(dict(times=times, cores=cores, other_cores=other, rmse=rmse)), flush=True)
    v["win"].Finalize()


def vtk_time(a, case_name, step):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--vtk-time", case_name, str(step),
           "--repeats", str(a.repeats), "--threads", str(a.threads), "--out", str(Path(a.out).resolve()),
           "--quiet", str(a.pair_quiet)]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    lines = [l for l in p.stdout.splitlines() if l.startswith("VTKTIME ")]
    if p.returncode != 0 or not lines:
        sys.exit(f"VTK timing failed for {case_name} at {step} mm:\n{p.stdout}\n{p.stderr}")
    return json.loads(lines[-1][len("VTKTIME "):])


def shortlist(rows, a, px, out, base, ref):
    """Time the rows that might be a VTK setting's partner again (see
    SHORTLIST): each row's time_ms becomes the median of all its runs
    (first_ms keeps its first, runs counts them)."""
    picked = []
    for vt, _ in partners(rows):
        ok = [o for o in as_accurate(rows, vt) if o.get("run")]
        for o in ok[:SHORTLIST]:
            if o["time_ms"] <= SHORTLIST_MARGIN * ok[0]["time_ms"] and all(o is not q for q in picked):
                picked.append(o)
    if a.shortlist_runs <= 0 or not picked:
        return
    log("")
    log(f"Shortlist: {len(picked)} rows that might be a partner, {a.shortlist_runs} more runs each "
        "(fresh processes, alternating order):")
    quiet, common.QUIET_S = common.QUIET_S, a.pair_quiet
    times = {id(o): [o["time_ms"]] for o in picked}
    for k in range(a.shortlist_runs):
        for o in picked if k % 2 == 0 else picked[::-1]:
            run, db, render = o["run"]
            img, st = run_parallax(px, f"{run}-short{k + 1}", base, db, render, out, a.frames, False)
            rmse = image_error(img, ref)[0]
            if rmse != o["rmse"]:
                sys.exit(f"{run}: the image changed between runs (RMSE {o['rmse']:.6e} → {rmse:.6e})")
            times[id(o)].append(st["render_ms"])
    common.QUIET_S = quiet
    for o in picked:
        ts = times[id(o)]
        o["first_ms"] = o["time_ms"]
        o["time_ms"] = statistics.median(ts)
        o["runs"] = len(ts)
        log(f"  {o['config']} {o['step_mm']} mm: {', '.join(f'{t:.1f}' for t in ts)} ms → "
            f"median {o['time_ms']:.1f} ms")


def confirm_pairs(case, rows, a, px, out, base):
    """Each VTK setting and its partner, `a.pairs` times in alternating
    order, each side in a fresh process; one row per pair."""
    name = case["name"]
    result = []
    if a.pairs <= 0:
        return result
    quiet, common.QUIET_S = common.QUIET_S, a.pair_quiet
    log("")
    log(f"Alternating pairs ({a.pairs} per VTK setting, each side in a fresh process; "
        "VTK first in odd pairs):")
    for vt, o in partners(rows):
        if o is None:
            continue
        run, db, render = o["run"]
        for k in range(a.pairs):
            sides = ["vtk", "parallax"] if k % 2 == 0 else ["parallax", "vtk"]
            got = {}
            for side in sides:
                if side == "vtk":
                    got["vtk"] = vtk_time(a, name, vt["step_mm"])
                else:
                    img, st = run_parallax(px, f"{run}-pair{k + 1}", base, db, render, out, a.frames, False)
                    got["parallax"] = st
                    got["parallax_rmse"] = image_error(img, np.load(out / f"{name}-reference.npy"))[0]
            t_vtk = statistics.median(got["vtk"]["times"])
            t_px = got["parallax"]["render_ms"]
            if got["parallax_rmse"] != o["rmse"]:
                sys.exit(f"{name}: the partner's image changed between runs "
                         f"(RMSE {o['rmse']:.6e} → {got['parallax_rmse']:.6e})")
            result.append(dict(case=name, vtk_step_mm=vt["step_mm"], vtk_rmse=vt["rmse"],
                               pair_vtk_rmse=got["vtk"]["rmse"], partner=o["config"],
                               partner_step_mm=o["step_mm"], partner_rmse=o["rmse"], pair=k + 1,
                               first=sides[0], vtk_ms=t_vtk, parallax_ms=t_px, ratio=t_px / t_vtk))
            log(f"  VTK {vt['step_mm']:5} mm ↔ {o['config']} {o['step_mm']} mm, pair {k + 1} "
                f"({sides[0]} first): VTK {t_vtk:7.1f} ms, Parallax {t_px:7.1f} ms, ratio {t_px / t_vtk:.2f}")
    common.QUIET_S = quiet
    return result


def pair_lines(pair_rows):
    """Per VTK setting: the ratio of the medians over its pairs, and the
    spread of the pairs' own ratios."""
    lines = []
    steps = sorted({r["vtk_step_mm"] for r in pair_rows})
    for s in steps:
        rs = [r for r in pair_rows if r["vtk_step_mm"] == s]
        v = statistics.median(r["vtk_ms"] for r in rs)
        p = statistics.median(r["parallax_ms"] for r in rs)
        q = [r["ratio"] for r in rs]
        vts = ", ".join(format(r["vtk_ms"], ".0f") for r in rs)
        pxs = ", ".join(format(r["parallax_ms"], ".0f") for r in rs)
        lines.append(f"VTK {s:5} mm ↔ {rs[0]['partner']} {rs[0]['partner_step_mm']} mm: VTK {vts} ms, "
                     f"Parallax {pxs} ms: ratio of medians {p / v:.2f} (pairs {min(q):.2f}–{max(q):.2f})")
    return lines


# --------------------------------------------------------------------------

def fmt(x, spec):
    return "" if x == "" or x is None else format(x, spec)


# The comparisons of one run: the translucent brain (the full study: both
# brick encodings, early termination matched and off, VTK as it comes too),
# then an opaque view and a CT that is mostly air (8-bit bricks, early
# termination matched, VTK on Parallax's domain).
# `preint`: the ladders' render.preintegration. The closed form's time
# over the 2D table's at the partners of VTK's settings (bench/
# settings_closed_form_{brain,skin,ct}.csv, docs/performance.md
# "Pre-integration per case"): the brain (4 pieces) 0.86–0.91, the skin (2)
# 0.87; the CT (12) 0.96 at 0.88 mm but 1.24 at 5 mm.
CASES = [
    dict(name="colin27-brain", title="Colin27 MRI, translucent brain", volume="colin27",
         tf="../configs/tf/colin27-brain.toml", full=True, preint="analytic"),
    dict(name="colin27-skin", title="Colin27 MRI, opaque skin", volume="colin27",
         tf="../configs/tf/colin27-skin.toml", full=False, preint="analytic"),
    dict(name="ct-bone", title="CT phantom 256³ (i16 Hounsfield units), CT-Bone", volume="ct",
         tf="../configs/tf/ct-bone.toml", full=False, preint="2d"),
    # Issue 40's case: a clinical chest CT's geometry (512 × 512 × 48 i16,
    # 1 × 1 × 10.7 mm voxels, mostly air, a scanner's noise), imported with
    # the defaults, under 3D Slicer's CT-Soft-Tissue preset, and Parallax
    # at its default pre-integration with only step_factor and accuracy
    # varied (`defaults_only`).
    dict(name="ct-thick", title="thick-slice CT 512×512×48 (i16, 1×1×10.7 mm), CT-Soft-Tissue",
         volume="ct-thick", tf="../configs/tf/ct-soft-tissue.toml", full=False, preint=None,
         defaults_only=True),
]

# The NRRD each non-Colin27 volume is read from, and the stem of its
# databases (bench/vtk_compare.sh writes and imports them).
VOLUME_FILES = {"ct": "ct256", "ct-thick": "ct-thick"}
# The defaults-only ladders: accuracy (pixels per voxel) against step_factor.
# Below 1, accuracy also shrinks the finest level's step (sub-pixel
# accuracy); above, it coarsens the cut. The tissue's voxels can be opaque
# under CT-Soft-Tissue, so they are held to accuracy / 2
# (render.opaque_detail): on this view 300 / 300 / 98 / 44 / 20 / 8 bricks
# at 1 / 2 / 4 / 8 / 16 / 32.
DEFAULT_ACCURACIES = [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0]
# Their step_factors (the "step_mm" column: rays cross the slices along y,
# so at the finest level step_factor 1 is 1 mm; a coarser level's voxel
# is larger by its level's factor).
DEFAULT_STEPS = [0.25, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0]


def read_case_volume(case, out):
    if case["volume"] == "colin27":
        return vtk_read_volume()
    return read_nrrd(out / f"{VOLUME_FILES[case['volume']]}.nrrd")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parallax", default=str(ROOT / "target/release/parallax"))
    ap.add_argument("--out", default=str(ROOT / "out/bench-vtk"))
    ap.add_argument("--frames", type=int, default=16, help="frames per Parallax run (timed: the median of the last half)")
    ap.add_argument("--repeats", type=int, default=5, help="timed VTK renders (median)")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 2, help="VTK ray cast threads")
    ap.add_argument("--reuse", action="store_true", help="reuse Parallax runs whose scene is unchanged")
    ap.add_argument("--csv", default=str(BENCH / "vtk_results.csv"))
    ap.add_argument("--cases", default=",".join(c["name"] for c in CASES),
                    help="which comparisons (default: all)")
    ap.add_argument("--pairs", type=int, default=3,
                    help="alternating pairs per VTK setting and its partner (0: none)")
    ap.add_argument("--pairs-csv", default=str(BENCH / "vtk_pairs.csv"))
    ap.add_argument("--shortlist-runs", type=int, default=SHORTLIST_RUNS,
                    help="further runs of each row that might be a partner (0: one run decides)")
    ap.add_argument("--vtk-time", nargs=2, metavar=("CASE", "STEP"),
                    help="(internal) time VTK alone in this process and print the result")
    ap.add_argument("--quiet", type=float, default=common.QUIET_S,
                    help="seconds without other processes' load before each timed section")
    ap.add_argument("--pair-quiet", type=float, default=3.0,
                    help="the same before each side of an alternating pair")
    a = ap.parse_args()
    common.QUIET_S = a.quiet
    if a.vtk_time:
        vtk_time_main(a)
        return

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    px = Path(a.parallax)
    volumes = {}
    rows = []
    pair_rows = []
    summary = []
    for case in CASES:
        if case["name"] not in a.cases.split(","):
            continue
        if case["volume"] not in volumes:
            volumes[case["volume"]] = read_case_volume(case, out)
        log("")
        log(f"==== {case['title']} ({case['name']})")
        case_rows, case_pairs = run_case(case, a, px, out, volumes[case["volume"]])
        rows += case_rows
        pair_rows += case_pairs
        summary.append((case, case_rows, case_pairs))

    # ---- Table.
    cols = ["case", "renderer", "config", "step_mm", "early_termination", "readback", "time_ms",
            "rmse", "max_abs", "psnr_db", "cores", "other_cores"] + STAGES + ["light_frame_render_ms", "bricks", "adequate", "runs", "first_ms"]
    with open(a.csv, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        wr.writeheader()
        for r in rows:
            rr = dict(r)
            for k in ["time_ms", "light_frame_render_ms", "first_ms"] + STAGES:
                rr[k] = fmt(rr.get(k, ""), ".1f")
            for k in ["cores", "other_cores"]:
                rr[k] = fmt(rr[k], ".2f")
            rr["rmse"] = f"{rr['rmse']:.4e}"
            rr["max_abs"] = f"{rr['max_abs']:.4e}"
            rr["psnr_db"] = f"{rr['psnr_db']:.2f}"
            wr.writerow(rr)
    log("")
    log("Summary: for each VTK setting (ray-cast image on Parallax's domain), the fastest Parallax "
        "setting with early termination matched and an RMSE no larger, as the time ratio Parallax / VTK:")
    for case, case_rows, _ in summary:
        log(f"  {case['title']}:")
        for line in equal_error_pairs(case_rows):
            log("    " + line)
    log(f"\nwrote {a.csv}")
    if pair_rows:
        pcols = ["case", "vtk_step_mm", "vtk_rmse", "pair_vtk_rmse", "partner", "partner_step_mm",
                 "partner_rmse", "pair", "first", "vtk_ms", "parallax_ms", "ratio"]
        with open(a.pairs_csv, "w", newline="") as f:
            wr = csv.DictWriter(f, fieldnames=pcols)
            wr.writeheader()
            for r in pair_rows:
                rr = dict(r)
                for k in ["vtk_rmse", "partner_rmse"]:
                    rr[k] = f"{rr[k]:.4e}"
                rr["pair_vtk_rmse"] = fmt(rr["pair_vtk_rmse"], ".4e")
                for k in ["vtk_ms", "parallax_ms"]:
                    rr[k] = f"{rr[k]:.1f}"
                rr["ratio"] = f"{rr['ratio']:.3f}"
                wr.writerow(rr)
        log("")
        log("The same pairs timed again, alternating, each side in a fresh process "
            f"({a.pairs} pairs per VTK setting; ratio Parallax / VTK):")
        for case, _, case_pairs in summary:
            log(f"  {case['title']}:")
            for line in pair_lines(case_pairs):
                log("    " + line)
        log(f"\nwrote {a.pairs_csv}")


def as_accurate(rows, vt):
    """The Parallax rows with early termination matched and an RMSE no
    larger than VTK row `vt`'s, fastest first."""
    return sorted((o for o in rows if o["renderer"] == "parallax" and o["early_termination"] < 1
                   and o["rmse"] <= vt["rmse"]), key=lambda r: r["time_ms"])


def partners(rows):
    """Each VTK setting (box domain, ray-cast image) with the fastest
    Parallax setting as accurate (`as_accurate`; None when there is none)."""
    out = []
    for vt in rows:
        if not (vt["renderer"] == "vtk" and vt["config"].startswith("box") and vt["readback"].startswith("ray")):
            continue
        ok = as_accurate(rows, vt)
        out.append((vt, ok[0] if ok else None))
    return out


def equal_error_pairs(rows):
    lines = []
    for vt, o in partners(rows):
        if o is None:
            lines.append(f"VTK {vt['step_mm']:5} mm (RMSE {vt['rmse']:.2e}, {vt['time_ms']:6.1f} ms): "
                         "no Parallax setting as accurate")
            continue
        lines.append(f"VTK {vt['step_mm']:5} mm (RMSE {vt['rmse']:.2e}, {vt['time_ms']:6.1f} ms) ↔ Parallax "
                     f"{o['config']} {o['step_mm']} mm (RMSE {o['rmse']:.2e}, {o['time_ms']:6.1f} ms): "
                     f"ratio {o['time_ms'] / vt['time_ms']:.2f}")
    return lines


def parallax_row(case, config, step, et, st, rmse, mx, psnr, run=None):
    """One Parallax run's row of the table; `run`: (name, database, render
    settings), what the alternating pairs need to run it again."""
    return dict(case=case, renderer="parallax", config=config, run=run,
                step_mm=step, early_termination=round(et, 5), readback="float32",
                time_ms=st["render_ms"], rmse=rmse, max_abs=mx, psnr_db=psnr,
                cores=st["cores"], other_cores=st["other_cores"],
                light_frame_render_ms=st["light_frame_render_ms"],
                bricks=st["bricks"], adequate=st["adequate"], runs=1,
                **{k: st[k] for k in STAGES})


def case_scene(case):
    """bench/vtk_scene.toml with the case's transfer function."""
    base = tomllib.loads((BENCH / "vtk_scene.toml").read_text())
    base["transfer_function"] = case["tf"]
    return base


def run_case(case, a, px, out, volume):
    name = case["name"]
    stem = "colin27" if case["volume"] == "colin27" else VOLUME_FILES[case["volume"]]
    files = {"full": f"{stem}-full.pxo", "8-bit": f"{stem}-8bit.pxo",
             "full-b64": f"{stem}-full-b64.pxo", "8-bit-b64": f"{stem}-8bit-b64.pxo"}
    kinds = ["full", "8-bit"] if case.get("defaults_only") else list(files)
    dbs = {k: (out / files[k]).resolve() for k in kinds}
    for k, p in dbs.items():
        if not p.exists():
            sys.exit(f"{p} missing: run bench/vtk_compare.sh (it imports the databases)")

    base = case_scene(case)
    tf = load_tf((BENCH / base["transfer_function"]).resolve())
    pl = base["placement"]
    dims, spacing = volume[1], volume[2]
    if case["volume"] != "colin27":
        log(f"air (below -900 HU): {(volume[3] < -900).mean() * 100:.0f}% of the voxels")
    extent = tuple(d * s for d, s in zip(dims, spacing))     # N·s: (181, 217, 181) mm
    placement = Placement(pl["center"], pl["size"], pl["rotation_deg"], extent)
    log(f"volume {dims} voxels of {spacing} mm, box {extent} mm; voxel order checked against the file")

    # ---- Parallax: the reference, then the timed configurations.
    log("Parallax renders (lavapipe unless PARALLAX_ADAPTER says otherwise):")
    # Accuracy 0.01 draws the finest level everywhere at a quarter of the
    # step (sub-pixel accuracy): 1/16 of a voxel.
    ref_render = dict(step_factor=0.25, interpolation="exact", accuracy=0.01,
                      early_termination=1.0, visibility_feedback=False,
                      cpu_cache_mb=2048, gpu_cache_mb=1024, upload_budget=100000)
    ref, ref_stats = run_parallax(px, f"{name}-reference", base, dbs["full"], ref_render, out,
                                  min(a.frames, 8), a.reuse, timed=False)     # only its image counts
    if not ref_stats["adequate"]:
        log("  WARNING: the reference's cut was not adequate over its last frames")

    rows = []
    ours = {}
    for bricks in ["8-bit", "full"] if case["full"] else ["8-bit"]:
        ets = [("vtk", VTK_EARLY_TERMINATION), ("off", 1.0)] if case["full"] else [("vtk", VTK_EARLY_TERMINATION)]
        for et_name, et in ets:
            for s in STEPS + (EXTRA_STEPS if et < 1 else []):
                run = f"{name}-ours-{bricks}-step{s}-et{et_name}"
                img, st = run_parallax(px, run, base, dbs[bricks],
                                       dict(step_factor=s, early_termination=et), out, a.frames, a.reuse)
                rmse, mx, psnr = image_error(img, ref)
                ours[f"ours-{bricks}-step{s}-et{et_name}"] = img
                rows.append(parallax_row(name, f"{bricks} bricks", s, et, st, rmse, mx, psnr,
                                         (run, dbs[bricks], dict(step_factor=s, early_termination=et))))

    # The ladders, by label: on 8-bit and on full-precision bricks (a float
    # pool read with the 2D table or the closed form fetches each sample a
    # pass ahead, LOOKAHEAD; which kind is faster depends on the case and
    # the CPU: every brain partner of the last Zen 2 run is on 8-bit
    # bricks, bench/vtk_pairs_zen2.csv, while a Zen 5 run picks both,
    # bench/vtk_pairs_zen5_soa.csv); and level 1 of the float bricks of 64,
    # where a case's error allows it (the opaque skin at VTK's 2 and 4 mm:
    # half the leaves and a shorter descent per ray; docs/performance.md,
    # "Against VTK's CPU ray caster").
    preint = case["preint"]
    ladders = {}
    if case.get("defaults_only"):
        # The default import (8-bit bricks of 32) and pre-integration;
        # only accuracy and step_factor move. Rays cross the slices along
        # y here, so a step of 1 mm is step_factor 1.
        for acc in DEFAULT_ACCURACIES:
            ladders[f"defaults, accuracy {acc:g}"] = Ladder(
                "8-bit", DEFAULT_STEPS, 1.0, dict(accuracy=acc) if acc != 1.0 else None, f"-acc{acc:g}")
    else:
        label = PREINT_LABELS[preint]
        for kind in ["8-bit", "full"]:
            ladders[f"{kind} bricks, {label}"] = Ladder(kind, TABLE_STEPS)
            ladders[f"{kind} bricks of 64, {label}"] = Ladder(f"{kind}-b64", BIG_BRICK_STEPS)
        ladders[f"full bricks of 64, {label}, level 1"] = Ladder(
            "full-b64", COARSE_STEPS, COARSE_VOXEL_MM, dict(accuracy=COARSE_ACCURACY, opaque_detail=1.0), "-level1")

    def table_run(label, s):
        ld = ladders[label]
        run = f"{name}-ours-{ld.db}-{preint or 'default'}{ld.tag}-step{s}-etvtk"
        render = dict(step_factor=round(s / ld.voxel_mm, 4), early_termination=VTK_EARLY_TERMINATION,
                      **(dict(preintegration=preint) if preint else {}), **(ld.render or {}))
        img, st = run_parallax(px, run, base, dbs[ld.db], render, out, a.frames, a.reuse)
        rmse, mx, psnr = image_error(img, ref)
        row = parallax_row(name, label, s, VTK_EARLY_TERMINATION, st, rmse, mx, psnr,
                           (run, dbs[ld.db], render))
        rows.append(row)
        return row

    for label, ld in ladders.items():
        for s in ld.steps:
            table_run(label, s)

    # ---- VTK, on Parallax's domain (padded + cropped) and as it comes.
    log("VTK vtkFixedPointVolumeRayCastMapper:")
    vtk_imgs = {}
    infos = {}
    for domain in ["box", "centres"] if case["full"] else ["box"]:
        v = vtk_setup(tf, placement, a.threads, domain, volume)
        info = infos[domain] = v["info"]
        log(f"  domain '{domain}':")
        for k, val in info.items():
            log(f"    {k}: {val}")
        b = info["volume_bounds"]
        lo = -0.5 if domain == "box" else 0.5
        for ax in range(3):
            assert abs(b[2 * ax] - lo * spacing[ax]) < 1e-9 and abs(b[2 * ax + 1] - extent[ax] + lo * spacing[ax]) < 1e-9, b
        for s in [0.125] + STEPS + EXTRA_STEPS:
            times, cores, other, fb, rc = vtk_run(v, s, a.repeats)
            t = statistics.median(times)
            log(f"    sample distance {s} mm: Render() {', '.join(f'{x:.0f}' for x in times)} ms → "
                f"median {t:.0f} ms, {cores:.2f} cores busy")
            vtk_imgs[(domain, s)] = (fb, rc)
            reads = [("ray-cast image 15-bit", rc), ("framebuffer 8-bit", fb)]
            for readback, img in reads if domain == "box" and case["full"] else reads[:1]:
                rmse, mx, psnr = image_error(img, ref)
                rows.append(dict(case=name, renderer="vtk",
                                 config="box [0,N·s]" if domain == "box" else "voxel-centre box",
                                 step_mm=s, early_termination=round(VTK_EARLY_TERMINATION, 5),
                                 readback=readback, time_ms=t, rmse=rmse, max_abs=mx, psnr_db=psnr,
                                 cores=cores, other_cores=other, bricks="", adequate="", light_frame_render_ms="",
                                 **{k: "" for k in STAGES}))
        v["win"].Finalize()
        del v

    # ---- Between the rungs: for each VTK setting, the ladder that holds
    # its partner is bisected (REFINE times) between that ladder's largest
    # step as accurate as VTK and its next step, so that the partner's step
    # is not set by the ladder's spacing. The error is not monotonic in the
    # step everywhere; every step tried is a row of its own, and the
    # partner is still the fastest row as accurate as VTK.
    log("Parallax between the rungs of the partner's ladder:")
    for vt, o in partners(rows):
        if o is None or o["config"] not in ladders:
            continue
        ladder = [r for r in rows if r["renderer"] == "parallax" and r["config"] == o["config"]]
        lo = max((r for r in ladder if r["rmse"] <= vt["rmse"]), key=lambda r: r["step_mm"])
        above = [r for r in ladder if r["step_mm"] > lo["step_mm"]]
        if not above:
            continue
        hi = min(above, key=lambda r: r["step_mm"])
        for _ in range(REFINE):
            if hi["step_mm"] - lo["step_mm"] < 0.1:
                break
            s = round(0.5 * (lo["step_mm"] + hi["step_mm"]), 2)
            row = next((r for r in ladder if r["step_mm"] == s), None) or table_run(o["config"], s)
            ladder.append(row)
            if row["rmse"] <= vt["rmse"]:
                lo = row
            else:
                hi = row

    shortlist(rows, a, px, out, base, ref)

    # ---- Alignment: VTK's image must land on ours.
    c_ref = alpha_centroid(ref)
    log("Alignment (alpha-weighted centroid, pixels from the top-left corner; step 0.25 mm):")
    log(f"  reference                     ({c_ref[0]:.3f}, {c_ref[1]:.3f})")
    checks = [("vtk box, ray-cast image", vtk_imgs[("box", 0.25)][1], True),
              ("vtk box, framebuffer", vtk_imgs[("box", 0.25)][0], True),
              ("parallax 8-bit", ours["ours-8-bit-step0.25-etvtk"], True)]
    if case["full"]:
        checks.insert(2, ("vtk centres, ray-cast image", vtk_imgs[("centres", 0.25)][1], False))
    for nm, img, strict in checks:
        c = alpha_centroid(img)
        sh = best_shift(img, ref)
        d = (c[0] - c_ref[0], c[1] - c_ref[1])
        log(f"  {nm:29s} ({c[0]:.3f}, {c[1]:.3f})  Δ = ({d[0]:+.3f}, {d[1]:+.3f}) px, "
            f"best whole-pixel shift {sh}")
        if strict:
            assert abs(d[0]) < 1.0 and abs(d[1]) < 1.0, f"{nm} is misaligned"
            assert sh == (0, 0), f"{nm} matches best when shifted by {sh}"
    rc = vtk_imgs[("box", 0.25)][1]
    log(f"  pixels with A > 1e-3: reference {(ref[..., 3] > 1e-3).sum()}, vtk {(rc[..., 3] > 1e-3).sum()}")

    # ---- Pictures: reference | VTK 0.5 mm | ours 0.5 mm 8-bit, and 10×|error|.
    fb5, rc5 = vtk_imgs[("box", 0.5)]
    o5 = ours["ours-8-bit-step0.5-etvtk"]
    top = np.concatenate([to_srgb8(ref), to_srgb8(rc5), to_srgb8(o5)], axis=1)
    err = lambda x: (np.clip(np.abs(x - ref).max(axis=-1) * 10.0, 0, 1) * 255).astype(np.uint8)
    bot = np.concatenate([np.repeat(err(x)[..., None], 3, axis=-1) for x in (ref, rc5, o5)], axis=1)
    write_png(out / f"{name}-compare.png", np.concatenate([top, bot], axis=0))
    np.save(out / f"{name}-reference.npy", ref)
    np.save(out / f"{name}-vtk_step0.5_raycast.npy", rc5)
    np.save(out / f"{name}-vtk_step0.5_framebuffer.npy", fb5)
    if case["full"]:
        np.save(out / f"{name}-vtk_centres_step0.5_raycast.npy", vtk_imgs[("centres", 0.5)][1])

    log("")
    log(f"Reference: Parallax, full bricks, step 1/16 mm, exact interpolation, no early termination "
        f"(render {ref_stats['render_ms']:.0f} ms, {ref_stats['bricks']} bricks).")
    log(f"{'renderer':9s} {'config':17s} {'step':>5s} {'ET':>7s} {'readback':22s} {'ms':>8s} "
        f"{'RMSE':>10s} {'max|e|':>9s} {'PSNR':>6s} {'cores':>5s}")
    for r in rows:
        log(f"{r['renderer']:9s} {r['config']:17s} {r['step_mm']:5.3g} {r['early_termination']:7.5f} "
            f"{r['readback']:22s} {r['time_ms']:8.1f} {r['rmse']:10.3e} {r['max_abs']:9.2e} "
            f"{r['psnr_db']:6.1f} {r['cores']:5.2f}")

    log("")
    log("Time ratio Parallax / VTK at the same step (render_ms vs Render() wall time), "
        "early termination matched to VTK's, VTK on the box domain:")
    for s in STEPS:
        vt = next(r for r in rows if r["renderer"] == "vtk" and r["step_mm"] == s
                  and r["config"].startswith("box") and r["readback"].startswith("ray"))
        for bricks in ["8-bit", "full"] if case["full"] else ["8-bit"]:
            o = next(r for r in rows if r["renderer"] == "parallax" and r["step_mm"] == s
                     and r["config"].startswith(bricks) and r["early_termination"] < 1)
            log(f"  step {s:4} mm, {bricks:5s}: {o['time_ms']:7.1f} / {vt['time_ms']:7.1f} ms = "
                f"{o['time_ms'] / vt['time_ms']:.2f}   (RMSE {o['rmse']:.2e} vs {vt['rmse']:.2e})")

    log("")
    log("At comparable error: for each VTK setting (box domain, ray-cast image), the fastest "
        "Parallax setting with early termination matched and an RMSE no larger:")
    for line in equal_error_pairs(rows):
        log("  " + line)

    log("")
    log("Where Parallax's time goes (median of the last half of the frames, ms):")
    log(f"  {'run':32s} " + " ".join(f"{k[:-3]:>8s}" for k in STAGES) + "  light frame  bricks adequate")
    for r in rows:
        if r["renderer"] == "parallax":
            nm = f"{r['config']} {r['step_mm']} ET {r['early_termination']}"
            log(f"  {nm:32s} " + " ".join(f"{r[k]:8.1f}" for k in STAGES)
                + f"  {r['light_frame_render_ms']:11.1f}  {r['bricks']:6} {r['adequate']}")
    log("  (light frame: render_ms of the lighter of frames 0-1, when nothing or only the coarse root "
        "brick is resident: an upper bound of the fixed per-frame cost of dispatch and image/feedback readback)")
    log(f"\nwrote {out / (name + '-compare.png')} (reference | VTK 0.5 mm | Parallax 8-bit 0.5 mm; "
        f"below: 10×|error|)")
    return rows, confirm_pairs(case, rows, a, px, out, base)


if __name__ == "__main__":
    main()
