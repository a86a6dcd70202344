#!/usr/bin/env bash
# Frame reconstruction (G10 §5) on a light field wall under mpirun: Colin27
# on the 8-projector test wall, 3 ranks (2 back ends), turned 1° per frame by
# configs/scripts/rotate-1deg.toml, rendered with and without
# reconstruction. Prints the speed-up (median frame time after the cut has
# settled) and the PSNR of every reconstructed projector image against the
# full render of the same frame.
# Usage: bash bench/reconstruction_wall.sh [FRAMES]   (default 24)
set -euo pipefail
cd "$(dirname "$0")/.."
PARALLAX_EXTRA_PACKAGES="python3-numpy" source scripts/setup.sh
frames="${1:-24}"
cargo build --release -q
bin=target/release/parallax
out=out/bench-reconstruction-wall
mkdir -p "$out"
colin=/usr/share/mricron/templates/ch2.nii.gz
[ -f "$out/colin27.pxo" ] || $bin import "$colin" -o "$out/colin27.pxo" >/dev/null
for mode in full reconstructed; do
  recon=false; [ "$mode" = reconstructed ] && recon=true
  sed -e "s#^volume = .*#volume = \"colin27.pxo\"#" \
      -e "s#^transfer_function = .*#transfer_function = \"$PWD/configs/tf/colin27-skin.toml\"#" \
      -e "s#^display = .*#display = \"$PWD/configs/displays/wall8/display.toml\"#" \
      -e "s#^\[render\]#[render]\nreconstruction = $recon#" \
      configs/scenes/colin27-wall.toml > "$out/scene-$mode.toml"
  rm -rf "${out:?}/$mode"
  mpirun -n 3 $bin render --scene "$out/scene-$mode.toml" --script configs/scripts/rotate-1deg.toml \
    --frames "$frames" --sync --float --out "$out/$mode" >/dev/null
done
/usr/bin/python3 - "$out" "$frames" <<'PY'
import json, sys, glob, os
import numpy as np
out, frames = sys.argv[1], int(sys.argv[2])
def times(mode):
    rows = [json.loads(l) for l in open(f"{out}/{mode}/frontend.jsonl")]
    key = next(k for k in ("wall_ms", "frame_ms", "total_ms") if k in rows[0])
    return [r[key] for r in rows]
settle = min(8, frames // 2)
tf, tr = times("full")[settle:], times("reconstructed")[settle:]
psnr = []
for f in range(frames):
    for a in sorted(glob.glob(f"{out}/full/frame_{f:05d}/*.npy")):
        b = a.replace("/full/", "/reconstructed/")
        x, y = np.load(a).astype(np.float64), np.load(b).astype(np.float64)
        mse = np.mean((x - y) ** 2)
        psnr.append(99.0 if mse == 0 else 10 * np.log10(1.0 / mse))
later = psnr[settle * 8:]
print(f"{frames} frames, 8 projectors, mpirun -n 3: median frame full {np.median(tf):.1f} ms, "
      f"reconstructed {np.median(tr):.1f} ms: speed-up {np.median(tf) / np.median(tr):.2f}x; "
      f"PSNR of reconstructed projector images against full, frames {settle}+: "
      f"mean {np.mean(later):.1f} dB, worst {np.min(later):.1f} dB")
PY
