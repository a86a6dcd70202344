#!/usr/bin/env bash
# A TIFF stack larger than the import's memory budget imports within it:
# writes N slices of 1024×1024 uint16 (tifffile, one slice at a time), as a
# folder and as one multi-page file, imports each with --memory-mb 256 and
# prints the peak resident memory.
# Usage: bash bench/tiff_memory.sh [SLICES]   (default 256: 512 MiB of voxels)
set -euo pipefail
cd "$(dirname "$0")/.."
PARALLAX_EXTRA_PACKAGES="python3-tifffile python3-numpy" source scripts/setup.sh
n="${1:-256}"
cargo build --release -q
out=out/bench-tiff
mkdir -p "$out/stack"
[ -f "$out/stack.tif" ] || /usr/bin/python3 - "$out" "$n" <<'PY'
import sys, numpy as np, tifffile
out, n = sys.argv[1], int(sys.argv[2])
y, x = np.mgrid[0:1024, 0:1024]
with tifffile.TiffWriter(out + "/stack.tif", bigtiff=True) as multi:
    for k in range(n):
        s = ((np.sin(x / 40.0 + k / 30.0) * np.cos(y / 50.0) + 1) * 20000 + k).astype(np.uint16)
        tifffile.imwrite("%s/stack/z%d.tif" % (out, k), s)
        multi.write(s, contiguous=False)
PY
for input in "$out/stack" "$out/stack.tif"; do
  echo "== $input ($(du -sh "$input" | cut -f1) on disk, $((n * 2)) MiB of voxels)"
  target/release/parallax import "$input" -o "$out/stack.pxo" --spacing 1,1,1 --memory-mb 256
done
