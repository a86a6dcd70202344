#!/usr/bin/env python3
"""Where a coarse sample of the translucent brain goes, and what cheaper
samples would buy: times variants of the ray-casting kernel, each made from
the kernel the view really uses by one textual change, beside VTK's
vtkFixedPointVolumeRayCastMapper, in alternating rounds of fresh processes.

    python3 bench/kernel_variants.py [--rounds 3] [--csv bench/kernel_variants.csv] [--only NAME,...]

Needs what `bash bench/vtk_compare.sh` leaves in out/bench-vtk (the Colin27
databases, the brain's reference render) and a release build; imports the
database with bricks of 128 itself. The view, the transfer function and
the reference are bench/vtk_compare.py's (512×512, Colin27 translucent
brain, full-precision bricks, the 2D pre-integration table, early
termination matched to VTK's).

The kernel is dumped with PARALLAX_KERNEL_DUMP from a render of the base
scene, each variant written beside it and loaded with
PARALLAX_KERNEL_SOURCE (backend/src/raycast/shader.rs). Variants marked
"cost only" compute a wrong image on purpose: they take a part of the
sample's work away (the brick pool's filtered fetch, the table's, every
sample after a leaf's first) to measure what that part costs. The others
are whole renderers whose RMSE against the reference counts.

Each round runs every variant once, Parallax by `parallax render --sync`
(16 frames, the median render_ms of the last 8) and VTK by
`bench/vtk_compare.py --vtk-time` (one set-up, a warm-up and five timed
renders, the median), each in a fresh process after a few quiet seconds;
the table gives the median over the rounds.
"""
import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import vtk_compare as vc  # noqa: E402

ROOT = vc.ROOT
CASE = "colin27-brain"

# The pool's filtered fetch, the 2D table's, and the loop that ends a
# leaf's samples, as the composed kernel spells them.
POOL_FETCH = ("        return textureSampleLevel(pool, pool_sampler, "
              "(vec3<f32>(o) + local + 0.5) * frame.recip.xyz, 0.0).r;")
TABLE_FETCH = ("    return max(textureSampleLevel(preint_grid, grid_sampler, "
               "(g + 0.5) * frame.grid.z, 0.0),")
LEAF_LOOP = ("            // An all-empty leaf ends with its starting sample, at its exit.\n"
             "            if (tc >= t_exit) {")

# The 2D table's nearest node: one textureLoad instead of the bilinear fetch.
TABLE_NEAREST = "    return max(textureLoad(preint_grid, vec2<i32>(g + 0.5), 0),"
# A segment's opacity and colour weight α/τ̄ (segment_optics), and the same
# weight as d·(1 − x/2) without the division and the branch: the opacity,
# and so where rays end, is unchanged.
OPTICS = """    if (x < 1e-4) {
        a = x * (1.0 - 0.5 * x);
        w = smp.len * (1.0 - 0.5 * x);
    } else {
        a = 1.0 - exp(-x);
        w = a / max(smp.tau, 1e-30);
    }"""
PLAIN_OPTICS = """    a = 1.0 - exp(-x);
    w = smp.len * (1.0 - 0.5 * x);"""

# The sample loop without its lookahead (each pass fetching its own sample,
# not the next pass's): the kernel's LOOKAHEAD made false where it is read.
PLAIN_LOOP = [("if (LOOKAHEAD && tc < t_exit) {", "if (false && tc < t_exit) {"),
              ("            if (LOOKAHEAD) {\n", "            if (false) {\n")]

# A value of the position that costs a few operations and no fetch.
CHEAP_VALUE = "90.0 + 0.5 * local.x + 0.3 * local.y + 0.2 * local.z + f32(o.x)"

POOL_FROM_STORAGE = f"""        let f0 = floor(local);
        let w = local - f0;
        let i0 = vec3<u32>(vec3<i32>(f0) + o);
        let row = frame.pool.x * frame.pool.w;
        let slice = row * frame.pool.y * frame.pool.w;
        let b = i0.x + row * i0.y + slice * i0.z;
        let m = (1u << firstLeadingBit(arrayLength(&image))) - 1u;
        let c00 = mix(image[b & m].x, image[(b + 1u) & m].x, w.x);
        let c10 = mix(image[(b + row) & m].x, image[(b + row + 1u) & m].x, w.x);
        let c01 = mix(image[(b + slice) & m].x, image[(b + slice + 1u) & m].x, w.x);
        let c11 = mix(image[(b + slice + row) & m].x, image[(b + slice + row + 1u) & m].x, w.x);
        let v = mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
        return {CHEAP_VALUE} + 1e-30 * v;"""

# The segment's table fetch and compositing, as the composed kernel spells
# the start of that part of the sample loop.
SEGMENT = ("            var avg: vec4<f32>;\n"
           "            if (GRID_PREINT) {")
# The brain's transfer function is τ ≡ 0 (and so k̃ ≡ 0) up to this value
# (configs/tf/colin27-brain.toml).
ZERO_UP_TO = 25.0
# A segment whose two values both lie below the table's last node in that
# range reads only nodes that average zero: it adds nothing, exactly.
ZERO_SKIP = (f"            if ((max(s_prev, s) - frame.tf.x) * frame.grid.x\n"
             f"                < floor(({ZERO_UP_TO:.1f} - frame.tf.x) * frame.grid.x)) {{\n"
             "                s_prev = s;\n"
             "                e_prev = e;\n"
             "                tc = tn;\n"
             "                if (tc >= t_exit) {\n"
             "                    break;\n"
             "                }\n"
             "                continue;\n"
             "            }\n" + SEGMENT)
# A midpoint sample where a segment's two values differ by more than
# JUMP (data units): two half segments instead of one, refined where the
# scalar changes most.
JUMP = 60.0
REFINE_JUMPS = f"""            if (abs(s - s_prev) > {JUMP:.1f}) {{
                let tm = 0.5 * (tc + tn);
                let sm = sample_levels(lv, blend, o + d * tm);
                let half = grid_average(s_prev, sm);
                var first: Sample;
                first.len = tm - tc;
                first.tau = half.x;
                first.emission = half.yzw;
                first.alpha_scale = 1.0;
                first.alpha_mix = 0.0;
                accumulate(&acc, segment_optics(first, 1.0), first);
                s_prev = sm;
                tc = tm;
            }}
""" + SEGMENT
# Danskin and Hanrahan's idea ("Fast algorithms for volume ray tracing",
# 1992) of sampling less densely as the ray's accumulated opacity grows:
# each pass's next step h0·min(T^(−1/2), 4), T = 1 − α the transmittance
# so far (one segment behind, as the lookahead fetches the next sample
# before it composites), the grid re-anchored at the sample where the step
# changes. A segment's error reaches the pixel weighted by T.
OPACITY_STEP_GROWTH = "clamp(pow(max(1.0 - acc.alpha, 1e-12), -0.5), 1.0, 4.0)"
OPACITY_STEP = [
    ("        var tc = t;\n        var k = 1u;\n",
     f"        let h0 = h;\n        h = h0 * {OPACITY_STEP_GROWTH};\n        var ta = t;\n"
     "        var tc = t;\n        var k = 1u;\n"),
    ("            let tn = next_sample(&ray, t, h, &k, tc, t_exit);",
     "            let tn = next_sample(&ray, ta, h, &k, tc, t_exit);"),
    ("            tn_next = next_sample(&ray, t, h, &k, tc, t_exit);",
     "            tn_next = next_sample(&ray, ta, h, &k, tc, t_exit);"),
    ("                    tn_next = next_sample(&ray, t, h, &k, tn, t_exit);",
     f"                    let hb = h0 * {OPACITY_STEP_GROWTH};\n"
     "                    if (hb != h) {\n                        ta = tn;\n                        k = 1u;\n"
     "                        h = hb;\n                    }\n"
     "                    tn_next = next_sample(&ray, ta, h, &k, tn, t_exit);"),
]

# The comparison's one view as constants instead of four reads of the frame
# table (the 512 × 512 window of bench/vtk_display.toml); a `var`, so that
# naga does not fold it into the code that divides by its sub-frame.
VIEW_FETCH = "    let view = view_at(tile.x);\n"
CONSTANT_VIEW = ("    var view = GpuView(vec4<f32>({x0!r}, {y0!r}, {w!r}, {h!r}), "
                 "vec4<f32>({ex!r}, {ey!r}, {ez!r}, 0.0),\n"
                 "                       vec4<f32>({ex!r}, {ey!r}, {ez!r}, 0.0), "
                 "vec4<u32>({W}u, {H}u, 0u, 0u));\n").format(
    x0=-vc.SCREEN[0] / 2, y0=-vc.SCREEN[1] / 2, w=vc.SCREEN[0], h=vc.SCREEN[1],
    ex=float(vc.EYE[0]), ey=float(vc.EYE[1]), ez=float(vc.EYE[2]), W=vc.W, H=vc.H)

# name: (database, step in voxels, replacements, whether the image counts, what it is)
VARIANTS = {
    "base": ("full-b64", 5.0, [], True,
             "bricks of 64, 5 mm: the partner of VTK at 4 mm"),
    "bricks-128": ("full-b128", 5.0, [], True, "bricks of 128, 5 mm"),
    "plain-loop": ("full-b64", 5.0, PLAIN_LOOP, True,
                   "each pass fetching its own sample (no LOOKAHEAD)"),
    "table-nearest": ("full-b64", 5.0, [(TABLE_FETCH, TABLE_NEAREST)], True,
                      "the 2D table's nearest node (one textureLoad) instead of its bilinear fetch"),
    "pool-nearest": ("full-b64", 5.0,
                     [(POOL_FETCH, "        return textureLoad(pool, o + vec3<i32>(local + 0.5), 0).r;")],
                     True, "the nearest voxel (one textureLoad) instead of the trilinear filter"),
    "plain-1.62mm": ("full", 1.62, [], True, "bricks of 32, 1.62 mm: the partner of VTK at 1 mm"),
    "table-nearest-1.62mm": ("full", 1.62, [(TABLE_FETCH, TABLE_NEAREST)], True,
                             "the same with the 2D table's nearest node"),
    "plain-optics": ("full-b64", 5.0, [(OPTICS, PLAIN_OPTICS)], False,
                     "cost only: a segment's colour weight without its division and branch"),
    "zero-skip": ("full-b64", 5.0, [(SEGMENT, ZERO_SKIP)], True,
                  "segments with both values where the transfer function is zero skip the table "
                  "and the compositing (the same image)"),
    "constant-view": ("full-b64", 5.0, [(VIEW_FETCH, CONSTANT_VIEW)], True,
                      "the view as constants instead of four reads of the frame table (the same image)"),
    "refine-jumps": ("full-b64", 5.0, [(SEGMENT, REFINE_JUMPS)], True,
                     f"a midpoint sample where a segment's values differ by more than {JUMP:g}"),
    "opacity-step-5mm": ("full-b64", 5.0, OPACITY_STEP, True,
                         "the step growing as the ray's opacity does, up to 4×, from 5 mm"),
    "opacity-step-4mm": ("full-b64", 4.0, OPACITY_STEP, True, "the same from 4 mm"),
    "opacity-step-3mm": ("full-b64", 3.0, OPACITY_STEP, True, "the same from 3 mm"),
    "trilinear-4mm": ("full-b64", 4.0, [], True, "bricks of 64, 4 mm"),
    "trilinear-3mm": ("full-b64", 3.0, [], True, "bricks of 64, 3 mm: the partner of VTK at 2 mm"),
    "no-pool-fetch": ("full-b64", 5.0, [(POOL_FETCH, f"        return {CHEAP_VALUE};")], False,
                      "cost only: a few operations instead of the pool's filtered fetch"),
    "pool-from-storage": ("full-b64", 5.0, [(POOL_FETCH, POOL_FROM_STORAGE)], False,
                          "cost only: eight reads of a storage buffer (the image's, 4 MB, its offsets "
                          "the pool's wrapped) and the trilinear weights, instead of the texture unit"),
    "no-fetches": ("full-b64", 5.0,
                   [(POOL_FETCH, f"        return {CHEAP_VALUE};"),
                    (TABLE_FETCH, "    return max(vec4<f32>(g.x * 1e-4, g.y * 1e-3, 0.5, 0.4),")],
                   False, "cost only: neither fetch (the table's values made up)"),
    "no-samples": ("full-b64", 5.0,
                   [(LEAF_LOOP, LEAF_LOOP.replace("if (tc >= t_exit) {", "if (tc >= t_exit || true) {"))],
                   False, "cost only: rays, traversal and each leaf's first sample, no others"),
}
VTK_STEPS = [4.0, 2.0]


def dump_kernel(px, kdir, base, db, render):
    """The composed kernel a scene's render uses (PARALLAX_KERNEL_DUMP)."""
    kdir.mkdir(parents=True, exist_ok=True)
    dumped = kdir / "base.wgsl"
    env = dict(os.environ, PARALLAX_KERNEL_DUMP=str(dumped))
    vc.write_scene(kdir / "dump.toml", base, db, render)
    p = subprocess.run([px, "render", "--scene", str(kdir / "dump.toml"), "--frames", "1", "--out",
                        str(kdir / "dump")], env=env, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"dumping the kernel failed:\n{p.stdout}\n{p.stderr}")
    return dumped.read_text()


def write_variant(kdir, name, src, changes):
    """`src` with each (old, new) replacement made once; the file written."""
    text = src
    for old, new in changes:
        if text.count(old) != 1:
            sys.exit(f"{name}: the kernel has {text.count(old)} copies of {old!r}, not one: "
                     "update bench/kernel_variants.py to the kernel's source")
        text = text.replace(old, new)
    path = kdir / f"{name}.wgsl"
    path.write_text(text)
    return path


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
    vc.QUIET_S = a.quiet
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


def variant_arguments(doc, default_csv, variants):
    """The rounds' arguments and --only: (args, out, parallax, the variants
    to run, "base" first)."""
    def only(ap):
        ap.add_argument("--only", help="the variants to run, comma-separated (the base always runs)")
    a, out, px = rounds_arguments(doc, default_csv, only)
    names = list(variants)
    if a.only:
        names = ["base"] + [n for n in a.only.split(",") if n and n != "base"]
    for n in names:
        if n not in variants:
            sys.exit(f"--only: no variant {n!r} (there are {', '.join(variants)})")
    return a, out, px, names


def main():
    a, out, px, names = variant_arguments(__doc__, "kernel_variants.csv", VARIANTS)
    ref_path = out / f"{CASE}-reference.npy"
    dbs = {k: out / f"colin27-{k}.pxo" for k in ["full", "full-b64", "full-b128"]}
    if not dbs["full-b64"].exists() or not ref_path.exists():
        sys.exit(f"{dbs['full-b64']} or {ref_path} missing: run bash bench/vtk_compare.sh first")
    if not dbs["full-b128"].exists():
        subprocess.run([px, "import", str(vc.VOLUME), "-o", str(dbs["full-b128"]), "--quantize", "none",
                        "--brick", "128"], check=True, capture_output=True)
    base = vc.case_scene(next(c for c in vc.CASES if c["name"] == CASE))
    ref = vc.np.load(ref_path)

    def render(step):
        return dict(step_factor=step, early_termination=vc.VTK_EARLY_TERMINATION, preintegration="2d")

    # The kernel the base scene uses, and the variants made from it.
    kdir = out / "kernel-variants"
    src = dump_kernel(px, kdir, base, dbs["full-b64"], render(5.0))
    sources = {}
    for name in names:
        if VARIANTS[name][2]:
            sources[name] = write_variant(kdir, name, src, VARIANTS[name][2])

    times = {k: [] for k in names + [f"vtk-{s:g}mm" for s in VTK_STEPS]}
    errors = {}
    for r in range(1, a.rounds + 1):
        vc.log(f"round {r} of {a.rounds}")
        for s in VTK_STEPS:
            vc.wait_idle()
            p = subprocess.run([sys.executable, str(vc.BENCH / "vtk_compare.py"), "--vtk-time", CASE, str(s),
                                "--out", str(out)], capture_output=True, text=True)
            line = next((ln for ln in p.stdout.splitlines() if ln.startswith("VTKTIME ")), None)
            if p.returncode != 0 or line is None:
                sys.exit(f"VTK at {s} mm failed:\n{p.stdout}\n{p.stderr}")
            d = json.loads(line[len("VTKTIME "):])
            times[f"vtk-{s:g}mm"].append(statistics.median(d["times"]))
            errors[f"vtk-{s:g}mm"] = d["rmse"]
        for name in names:
            db, step = VARIANTS[name][:2]
            if name in sources:
                os.environ["PARALLAX_KERNEL_SOURCE"] = str(sources[name])
            else:
                os.environ.pop("PARALLAX_KERNEL_SOURCE", None)
            img, st = vc.run_parallax(px, f"kv-{name}", base, dbs[db], render(step), out, a.frames, False)
            os.environ.pop("PARALLAX_KERNEL_SOURCE", None)
            times[name].append(st["render_ms"])
            errors[name] = vc.image_error(img, ref)[0]

    med = {k: statistics.median(v) for k, v in times.items()}
    rows = []
    for k in times:
        what = VARIANTS[k][4] if k in VARIANTS else f"VTK at {k[4:-2]} mm"
        counts = VARIANTS[k][3] if k in VARIANTS else True
        rows.append(dict(variant=k, what=what, rmse=f"{errors[k]:.4e}" if counts else "",
                         render_ms=round(med[k], 2), runs_ms=" ".join(f"{t:.1f}" for t in times[k]),
                         ratio_to_base=round(med[k] / med["base"], 3)))
    write_csv(a.csv, rows)
    log_rounds(rows, "variant", "ratio_to_base", "base")
    pairs = [("base", "vtk-4mm"), ("pool-nearest", "vtk-4mm"), ("trilinear-3mm", "vtk-2mm")]
    vc.log("\nParallax / VTK at equal or lower error: " + ", ".join(
        f"{x} / {y} {med[x] / med[y]:.2f}" for x, y in pairs if x in med))
    vc.log(f"written: {a.csv}")


if __name__ == "__main__":
    main()
