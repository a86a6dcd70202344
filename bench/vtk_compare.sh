#!/usr/bin/env bash
# Parallax vs VTK's vtkFixedPointVolumeRayCastMapper on the Colin27 MRI
# (translucent brain, opaque skin) and a CT phantom that is mostly air
# (bench/vtk_compare.py says what is measured and how). Installs what it
# needs (vtk and numpy from PyPI; the project's own system packages through
# scripts/setup.sh; xvfb only if VTK cannot render off screen), builds,
# imports the two databases, then runs the comparison.
#
#   bash bench/vtk_compare.sh [--reuse]      (arguments go to vtk_compare.py)
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh

python3 -c 'import vtk, numpy' 2>/dev/null || python3 -m pip install --quiet vtk numpy

cargo build --release --locked 2>&1 | tail -n 3
px=target/release/parallax
out=out/bench-vtk
src=/usr/share/mricron/templates/ch2.nii.gz
mkdir -p "$out"
# Imported every run, so that the databases are in this build's format.
$px import "$src" -o "$out/colin27-full.pxo" --quantize none
$px import "$src" -o "$out/colin27-8bit.pxo" --quantize u8
# The same with bricks of 64 (fewer leaves along a ray).
$px import "$src" -o "$out/colin27-full-b64.pxo" --quantize none --brick 64
$px import "$src" -o "$out/colin27-8bit-b64.pxo" --quantize u8 --brick 64
# The CT: a 256³ head phantom in Hounsfield units, mostly air.
[ -f "$out/ct256.nrrd" ] || $px synth ct --size 256 --type i16 -o "$out/ct256.nrrd"
$px import "$out/ct256.nrrd" -o "$out/ct256-full.pxo" --quantize none
$px import "$out/ct256.nrrd" -o "$out/ct256-8bit.pxo" --quantize u8
$px import "$out/ct256.nrrd" -o "$out/ct256-full-b64.pxo" --quantize none --brick 64
$px import "$out/ct256.nrrd" -o "$out/ct256-8bit-b64.pxo" --quantize u8 --brick 64
# Issue 40's thick-slice CT: 512 × 512 × 48 voxels of 1 × 1 × 10.7 mm, the
# defaults (8-bit bricks of 32), and full bricks for the reference.
[ -f "$out/ct-thick.nrrd" ] || $px synth ct --size 512 --slices 48 --type i16 -o "$out/ct-thick.nrrd"
$px import "$out/ct-thick.nrrd" -o "$out/ct-thick-8bit.pxo"
$px import "$out/ct-thick.nrrd" -o "$out/ct-thick-full.pxo" --quantize none

# VTK renders off screen through EGL (or OSMesa) on recent PyPI wheels; fall
# back to a virtual X display only if that fails.
run=(python3)
if ! python3 - <<'EOF' >/dev/null 2>&1
import vtk
w = vtk.vtkRenderWindow(); w.SetOffScreenRendering(1); w.SetSize(8, 8)
w.AddRenderer(vtk.vtkRenderer()); w.Render()
EOF
then
  echo "VTK cannot render off screen here: using xvfb-run"
  command -v xvfb-run >/dev/null || { apt-get update -qq; DEBIAN_FRONTEND=noninteractive apt-get install -y -qq xvfb >/dev/null; }
  run=(xvfb-run -a -s "-screen 0 1024x768x24" python3)
fi
"${run[@]}" bench/vtk_compare.py "$@"
