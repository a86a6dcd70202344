#!/usr/bin/env python3
"""What the rays of one VTK-comparison view do: per ray, the samples its
leaves' marches take (each leaf's starting sample counted apart, and the
samples cut short at a leaf's exit), the leaves with data it integrates,
and the opacity it ends with; and how evenly the rays of a SIMD row (8 × 1
pixels of an 8 × 8 tile) share their work, which a CPU device runs in
lock step.

    python3 bench/ray_counts.py [--case colin27-brain] [--db full-b64]
        [--set step_factor=5.0]

Needs what `bash bench/vtk_compare.sh` leaves in out/bench-vtk and a
release build. The kernel the view uses is dumped (PARALLAX_KERNEL_DUMP),
changed to write those counts into its pixel instead of the colour, and
loaded back (PARALLAX_KERNEL_SOURCE); the image it renders is the counts,
not a picture, and the run is not timed.
"""
import argparse
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import kernel_variants as kv  # noqa: E402
import settings_rounds as sr  # noqa: E402
import vtk_compare as vc  # noqa: E402

# Each ray's starting samples count 1000, its samples cut short at a
# leaf's exit 1 000 000, on top of the sample loop's 1 (a ray takes fewer
# than 1000 of each).
CHANGES = [
    ("            s_prev = sample_levels(lv, blend, o + d * tn);\n"
     "            n_samples = n_samples + 1u;",
     "            s_prev = sample_levels(lv, blend, o + d * tn);\n"
     "            n_samples = n_samples + 1000u;"),
    ("            n_samples = n_samples + 1u;\n            var e: TfEnd;",
     "            n_samples = n_samples + 1u;\n"
     "            if (tn >= t_exit) {\n"
     "                n_samples = n_samples + 1000000u;\n"
     "            }\n"
     "            var e: TfEnd;"),
    ("    image[out] = vec4<f32>(acc.color, acc.alpha);",
     "    image[out] = vec4<f32>(f32(n_samples % 1000u) + f32(n_samples / 1000000u) * 1e-3,\n"
     "                           f32((n_samples / 1000u) % 1000u), f32(visited), acc.alpha);"),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", default="colin27-brain")
    ap.add_argument("--db", default="full-b64")
    ap.add_argument("--set", default="step_factor=5.0",
                    help="[render] settings over the comparison's (early termination at VTK's, the 2D table)")
    ap.add_argument("--parallax", default=str(vc.ROOT / "target/release/parallax"))
    ap.add_argument("--out", default=str(vc.ROOT / "out/bench-vtk"))
    a = ap.parse_args()
    out = Path(a.out).resolve()
    case = next(c for c in vc.CASES if c["name"] == a.case)
    stem = "colin27" if case["volume"] == "colin27" else "ct256"
    db = out / f"{stem}-{a.db}.pxo"
    _, _, render = sr.setting(f"counts:{a.db}:{a.set}")
    base = vc.case_scene(case)
    kdir = out / "ray-counts"
    src = kv.dump_kernel(a.parallax, kdir, base, db, render)
    path = kv.write_variant(kdir, "counts", src, CHANGES)
    rdir = kdir / "run"
    vc.write_scene(kdir / "scene.toml", base, db, render)
    env = dict(os.environ, PARALLAX_KERNEL_SOURCE=str(path))
    frames = 16
    p = subprocess.run([a.parallax, "render", "--scene", str(kdir / "scene.toml"), "--float",
                        "--frames", str(frames), "--out", str(rdir)], env=env, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"render failed:\n{p.stdout}\n{p.stderr}")
    img = vc.np.load(rdir / f"frame_{frames - 1:05d}" / "window.npy").astype(vc.np.float64)
    loop = vc.np.floor(img[..., 0])
    cut = vc.np.round((img[..., 0] - loop) * 1e3)
    first, leaves, alpha = img[..., 1], img[..., 2], img[..., 3]
    total = loop + first
    m = total > 0
    h, w = total.shape
    rows = total.reshape(h, w // 8, 8)
    busy = rows.max(axis=2) > 0
    share = rows.sum(axis=2)[busy].sum() / (8 * rows.max(axis=2)[busy]).sum()
    print(f"{a.case}, {a.db}, {a.set}: {int(m.sum())} rays meet data, {int(total.sum())} samples")
    print(f"per such ray: {total[m].mean():.1f} samples (median {vc.np.median(total[m]):.0f}): "
          f"{first[m].mean():.2f} starting a leaf's march, {cut[m].mean():.2f} cut short at a leaf's exit; "
          f"{leaves[m].mean():.2f} leaves with data; opacity {alpha[m].mean():.2f} on average, "
          f"{(alpha[m] >= vc.VTK_EARLY_TERMINATION - 1e-6).mean() * 100:.0f} % reach early termination")
    print(f"SIMD rows of 8 × 1 pixels: the rays' samples are {share * 100:.1f} % of the rows' longest ray's × 8")


if __name__ == "__main__":
    main()
