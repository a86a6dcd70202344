#!/usr/bin/env bash
# The demo: imports the Colin27 head MRI into the octree database and shows
# what is in it. Output goes to out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh
cargo build --release --locked 2>&1 | tail -n 3
px=target/release/parallax
out=out/demo
mkdir -p "$out"
src=/usr/share/mricron/templates/ch2.nii.gz
$px import "$src" -o "$out/colin27.pxo" --empty-below 10
$px info "$out/colin27.pxo" --verify
