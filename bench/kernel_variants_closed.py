#!/usr/bin/env python3
"""Where a coarse sample of the translucent brain goes with the closed-form
pre-integration, and what four more changes to the sample loop would buy:
variants of the kernel Parallax uses for the partner of VTK's 4 mm
(bricks of 64, render.preintegration = "analytic", 5.62 mm, early
termination matched to VTK's), timed in alternating rounds of fresh
processes, as bench/kernel_variants.py does for the 2D table's kernel.

    python3 bench/kernel_variants_closed.py [--rounds 3] [--csv bench/kernel_variants_closed.csv] [--only NAME,...]

Needs what `bash bench/vtk_compare.sh` leaves in out/bench-vtk (the
Colin27 databases of bricks of 64, the brain's reference render) and a
release build. The kernel is dumped with PARALLAX_KERNEL_DUMP, each variant
written from it by textual changes and loaded with PARALLAX_KERNEL_SOURCE.
Variants marked "cost only" compute a wrong image on purpose, to measure
what a part of the frame costs; the others are whole renderers whose RMSE
against the reference counts. Some rows change no code: the 8-bit bricks'
own kernel, filtered by lavapipe's 8-bit integer path (GALLIVM_PERF
empty, the driver's default) or by its float path
(GALLIVM_PERF=no_aos_sampling, which parallax sets unless told otherwise);
lavapipe with two or eight threads a core (LP_NUM_THREADS); the same
kernel on memory that glibc backs with transparent huge pages
(GLIBC_TUNABLES=glibc.malloc.hugetlb=1: lavapipe allocates the brick pool
with malloc); llvmpipe asked for 512-bit vectors
(LP_NATIVE_VECTOR_WIDTH=512); and llvmpipe held to SSE4.1
(GALLIUM_OVERRIDE_CPU_CAPS=sse4.1: no AVX, so no gather instructions).
"unroll-2" takes two samples a pass on the 8-bit bricks, the same samples
and image as their own kernel's ("8-bit-soa").

Each round runs every variant once (`parallax render --sync`, 16 frames,
the median render_ms of the last 8) after a few quiet seconds; the table
gives the median over the rounds.
"""
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import kernel_variants as kv  # noqa: E402
import vtk_compare as vc  # noqa: E402

CASE = "colin27-brain"
STEP = 5.62

# Every invocation ends at once. A CPU device still runs the body's code
# outside loops, masked, and one pass of each loop: what a frame costs
# before its rays do anything (dispatch, clears, read-back and that code).
RAYS_OFF = [("    load_constants();\n    let w = wg.x + wg.y * groups.x;\n",
             "    let w = wg.x + wg.y * groups.x;\n"
             "    if (w < 0xFFFFFFFFu) {\n        image[w] = vec4<f32>(0.0);\n        return;\n    }\n"
             "    load_constants();\n")]
# Rays, traversal and each leaf's set-up, no sample loop.
NO_SAMPLES = [(kv.LEAF_LOOP, kv.LEAF_LOOP.replace("if (tc >= t_exit) {", "if (tc >= t_exit || true) {"))]
# Every fetch within one texel of a fixed place in its brick: the same
# instructions, the data always in the first-level cache.
POOL_CACHED = [("    let local = clamp(p * leaf.to_local + leaf.shift, vec3<f32>(0.0), vec3<f32>(side - 1.0));\n",
                "    let local = vec3<f32>(8.0) + 0.999 * fract(p * leaf.to_local + leaf.shift);\n")]
# No sample at a leaf's exit: the last grid point inside the leaf ends its
# march, and the next leaf goes on from it, as a grid continued across
# leaves would (the segment up to the exit is left out: cost only).
NO_EXIT_CUT = [("    var tn = min(tk, t_exit);\n",
                "    var tn = tk;\n    if (*k == 0xFFFFFFFFu) {\n        tn = min(tk, t_exit);\n    }\n"),
               ("                tn = tn_next;\n                s = s_next;\n",
                "                tn = tn_next;\n                s = s_next;\n"
                "                if (tn > t_exit) {\n                    break;\n                }\n")]
# Each sample fetched two passes ahead of its segment instead of one.
LOOKAHEAD_2 = [
    ("""        var tn_next = tc;
        var s_next = s_prev;
        if (LOOKAHEAD && tc < t_exit) {
            tn_next = next_sample(&ray, t, h, &k, tc, t_exit);
            s_next = sample_levels(lv, blend, o + d * tn_next);
        }""", """        var tn_next = tc;
        var s_next = s_prev;
        var tn_next2 = tc;
        var s_next2 = s_prev;
        if (LOOKAHEAD && tc < t_exit) {
            tn_next = next_sample(&ray, t, h, &k, tc, t_exit);
            s_next = sample_levels(lv, blend, o + d * tn_next);
            if (tn_next < t_exit) {
                tn_next2 = next_sample(&ray, t, h, &k, tn_next, t_exit);
                s_next2 = sample_levels(lv, blend, o + d * tn_next2);
            }
        }"""),
    ("""                tn = tn_next;
                s = s_next;
                if (tn < t_exit) {
                    tn_next = next_sample(&ray, t, h, &k, tn, t_exit);
                    s_next = sample_levels(lv, blend, o + d * tn_next);
                }""", """                tn = tn_next;
                s = s_next;
                if (tn < t_exit) {
                    tn_next = tn_next2;
                    s_next = s_next2;
                    if (tn_next < t_exit) {
                        tn_next2 = next_sample(&ray, t, h, &k, tn_next, t_exit);
                        s_next2 = sample_levels(lv, blend, o + d * tn_next2);
                    }
                }"""),
]
# Each segment in two halves, the value at its middle from the cubic
# through the four samples around it (a quadratic through three at a
# leaf's ends), clamped to their range: a higher-order scalar along the
# ray from samples the loop already holds, at the price of a second
# closed form and compositing per pass.
CUBIC_HELPERS = """// The value at the middle of [x1, x2] of the cubic through four points.
fn cubic_mid(x0: f32, x1: f32, x2: f32, x3: f32, y0: f32, y1: f32, y2: f32, y3: f32) -> f32 {
    let x = 0.5 * (x1 + x2);
    let l0 = (x - x1) * (x - x2) * (x - x3) / ((x0 - x1) * (x0 - x2) * (x0 - x3));
    let l1 = (x - x0) * (x - x2) * (x - x3) / ((x1 - x0) * (x1 - x2) * (x1 - x3));
    let l2 = (x - x0) * (x - x1) * (x - x3) / ((x2 - x0) * (x2 - x1) * (x2 - x3));
    let l3 = (x - x0) * (x - x1) * (x - x2) / ((x3 - x0) * (x3 - x1) * (x3 - x2));
    return l0 * y0 + l1 * y1 + l2 * y2 + l3 * y3;
}
// The value at x of the quadratic through three points.
fn quad_at(x0: f32, x1: f32, x2: f32, y0: f32, y1: f32, y2: f32, x: f32) -> f32 {
    let l0 = (x - x1) * (x - x2) / ((x0 - x1) * (x0 - x2));
    let l1 = (x - x0) * (x - x2) / ((x1 - x0) * (x1 - x2));
    let l2 = (x - x0) * (x - x1) / ((x2 - x0) * (x2 - x1));
    return l0 * y0 + l1 * y1 + l2 * y2;
}

@compute @workgroup_size(8, 8, 1)
"""
CUBIC_MIDPOINT = [
    ("@compute @workgroup_size(8, 8, 1)\n", CUBIC_HELPERS),
    ("        var tn_next = tc;\n",
     "        var tn_next = tc;\n        var s_pp = 0.0;\n        var t_pp = 0.0;\n        var have_pp = false;\n"),
    ("""            var avg: vec4<f32>;
            if (ANALYTIC_PREINT) {
                avg = analytic_average(s_prev, s);""", """            var avg: vec4<f32>;
            let have_nx = tn < t_exit;
            var split = true;
            var mid = 0.0;
            if (have_pp && have_nx) {
                mid = cubic_mid(t_pp, tc, tn, tn_next, s_pp, s_prev, s, s_next);
            } else if (have_nx) {
                mid = quad_at(tc, tn, tn_next, s_prev, s, s_next, 0.5 * (tc + tn));
            } else if (have_pp) {
                mid = quad_at(t_pp, tc, tn, s_pp, s_prev, s, 0.5 * (tc + tn));
            } else {
                split = false;
            }
            var lo4 = min(s_prev, s);
            var hi4 = max(s_prev, s);
            if (have_pp) {
                lo4 = min(lo4, s_pp);
                hi4 = max(hi4, s_pp);
            }
            if (have_nx) {
                lo4 = min(lo4, s_next);
                hi4 = max(hi4, s_next);
            }
            mid = clamp(mid, lo4, hi4);
            var avg2 = vec4<f32>(0.0);
            if (!split) {
                avg = analytic_average(s_prev, s);
            } else {
                avg = analytic_average(s_prev, mid);
                avg2 = analytic_average(mid, s);
            }
            if (false) {"""),
    ("""            accumulate(&acc, segment_optics(smp, shade), smp);
            s_prev = s;""", """            if (!split) {
                accumulate(&acc, segment_optics(smp, shade), smp);
            } else {
                smp.len = 0.5 * (tn - tc);
                accumulate(&acc, segment_optics(smp, shade), smp);
                smp.tau = avg2.x;
                smp.emission = avg2.yzw;
                accumulate(&acc, segment_optics(smp, shade), smp);
            }
            s_pp = s_prev;
            t_pp = tc;
            have_pp = true;
            s_prev = s;"""),
]

# Two samples a pass, their fetches back to back (the kernel of bricks
# without LOOKAHEAD, the 8-bit ones): whatever lives across lavapipe's
# call to its filter is saved and restored once for two fetches instead of
# once for each; the second segment composited after the first, so the
# samples, their order and the image are the base's.
UNROLL_2 = [
    ("""            var tn: f32;
            var s: f32;
""", """            var tn: f32;
            var s: f32;
            var have2 = false;
            var tn2 = 0.0;
            var s2 = 0.0;
"""),
    ("""                tn = next_sample(&ray, t, h, &k, tc, t_exit);
                s = sample_levels(lv, blend, o + d * tn);
            }
""", """                tn = next_sample(&ray, t, h, &k, tc, t_exit);
                have2 = tn < t_exit;
                tn2 = tn;
                if (have2) {
                    tn2 = next_sample(&ray, t, h, &k, tn, t_exit);
                }
                s = sample_levels(lv, blend, o + d * tn);
                s2 = sample_levels(lv, blend, o + d * tn2);
            }
"""),
    ("""            if (bent || tc >= t_exit || terminated(acc)) {
                break;
            }
        }
""", """            if (bent || tc >= t_exit || terminated(acc)) {
                break;
            }
            if (have2) {
                let avg2 = analytic_average(s_prev, s2);
                var smp2: Sample;
                smp2.pos = o + d * (0.5 * (tc + tn2));
                smp2.len = tn2 - tc;
                smp2.dir = d;
                smp2.scalar = s2;
                smp2.tau = avg2.x;
                smp2.emission = avg2.yzw;
                smp2.alpha_scale = 1.0;
                smp2.alpha_mix = 0.0;
                smp2.material = frame.light;
                accumulate(&acc, segment_optics(smp2, 1.0), smp2);
                n_samples = n_samples + 1u;
                s_prev = s2;
                tc = tn2;
                if (tc >= t_exit || terminated(acc)) {
                    break;
                }
            }
        }
"""),
]

# name: (database, kernel changes, environment, whether the image counts, what it is)
VARIANTS = {
    "base": ("full-b64", [], {}, True, "bricks of 64, closed form, 5.62 mm: the partner of VTK at 4 mm"),
    "rays-off": ("full-b64", RAYS_OFF, {}, False,
                 "cost only: every invocation ends at once (dispatch, clears, read-back, the body run masked)"),
    "no-samples": ("full-b64", NO_SAMPLES, {}, False,
                   "cost only: rays, traversal and each leaf's set-up, no sample loop"),
    "pool-cached": ("full-b64", POOL_CACHED, {}, False,
                    "cost only: every fetch near one place of its brick (the data in the first-level cache)"),
    "no-exit-cut": ("full-b64", NO_EXIT_CUT, {}, False,
                    "cost only: no sample at a leaf's exit (the samples a grid continued across leaves takes)"),
    "lookahead-2": ("full-b64", LOOKAHEAD_2, {}, True, "each sample fetched two passes ahead instead of one"),
    "cubic-midpoint": ("full-b64", CUBIC_MIDPOINT, {}, True,
                       "each segment halved at a midpoint value from the cubic through the samples around it"),
    "8-bit": ("8bit-b64", [], {"GALLIVM_PERF": ""}, True,
              "the same kernel on 8-bit bricks (a quarter of the memory), filtered by gallivm's 8-bit integer path"),
    "huge-pages": ("full-b64", [], {"GLIBC_TUNABLES": "glibc.malloc.hugetlb=1"}, True,
                   "the same on transparent huge pages (glibc's malloc, which lavapipe's pool comes from)"),
    "vector-512": ("full-b64", [], {"LP_NATIVE_VECTOR_WIDTH": "512"}, True,
                   "the same with llvmpipe asked for 512-bit vectors (16 lanes)"),
    "8-bit-soa": ("8bit-b64", [], {"GALLIVM_PERF": "no_aos_sampling"}, True,
                  "8-bit bricks filtered by gallivm's float path (what parallax asks lavapipe for)"),
    "unroll-2": ("8bit-b64", UNROLL_2, {}, True,
                 "8-bit bricks, two samples a pass with their fetches back to back (the same samples and image)"),
    "no-avx": ("8bit-b64", [], {"GALLIUM_OVERRIDE_CPU_CAPS": "sse4.1"}, True,
               "8-bit bricks, llvmpipe held to SSE4.1: 4 lanes, no gather instructions, no FMA"),
    "threads-2x": ("full-b64", [], {"LP_NUM_THREADS": "4"}, True,
                   "lavapipe with two threads a core instead of four"),
    "threads-8x": ("full-b64", [], {"LP_NUM_THREADS": "16"}, True,
                   "lavapipe with eight threads a core instead of four"),
}


def main():
    a, out, px, names = kv.variant_arguments(__doc__, "kernel_variants_closed.csv", VARIANTS)
    ref_path = out / f"{CASE}-reference.npy"
    dbs = {k: out / f"colin27-{k}.pxo" for k in ["full-b64", "8bit-b64"]}
    for p in [*dbs.values(), ref_path]:
        if not p.exists():
            sys.exit(f"{p} missing: run bash bench/vtk_compare.sh first")
    base = vc.case_scene(next(c for c in vc.CASES if c["name"] == CASE))
    ref = vc.np.load(ref_path)
    render = dict(step_factor=STEP, early_termination=vc.VTK_EARLY_TERMINATION, preintegration="analytic")

    kdir = out / "kernel-variants-closed"
    src = kv.dump_kernel(px, kdir, base, dbs["full-b64"], render)
    sources = {n: kv.write_variant(kdir, n, src, VARIANTS[n][1]) for n in names if VARIANTS[n][1]}

    times = {n: [] for n in names}
    errors = {}
    for r in range(1, a.rounds + 1):
        vc.log(f"round {r} of {a.rounds}")
        for name in names:
            db, _, env, _, _ = VARIANTS[name]
            saved = {k: os.environ.get(k) for k in [*env, "PARALLAX_KERNEL_SOURCE"]}
            os.environ.update(env)
            if name in sources:
                os.environ["PARALLAX_KERNEL_SOURCE"] = str(sources[name])
            else:
                os.environ.pop("PARALLAX_KERNEL_SOURCE", None)
            try:
                img, st = vc.run_parallax(px, f"kvc-{name}", base, dbs[db], render, out, a.frames, False)
            finally:
                for k, v in saved.items():
                    if v is None:
                        os.environ.pop(k, None)
                    else:
                        os.environ[k] = v
            times[name].append(st["render_ms"])
            errors[name] = vc.image_error(img, ref)[0]

    med = {k: statistics.median(v) for k, v in times.items()}
    rows = [dict(variant=n, what=VARIANTS[n][4], rmse=f"{errors[n]:.4e}" if VARIANTS[n][3] else "",
                 render_ms=round(med[n], 2), runs_ms=" ".join(f"{t:.1f}" for t in times[n]),
                 ratio_to_base=round(med[n] / med["base"], 3)) for n in names]
    kv.write_csv(a.csv, rows)
    kv.log_rounds(rows, "variant", "ratio_to_base", "base")
    vc.log(f"written: {a.csv}")


if __name__ == "__main__":
    main()
