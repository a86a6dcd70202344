#!/usr/bin/env bash
# Instructions the ray-casting kernel executes on lavapipe, counted by
# valgrind's callgrind: a figure that does not depend on what else the
# machine is doing (timings on a shared 2-core machine vary by 10–25 %
# from run to run), for A/B comparisons of kernel changes.
#
#   bash bench/kernel_instructions.sh SCENE [FRAMES]
#   PX=/path/to/parallax bash bench/kernel_instructions.sh SCENE   (another build, for A/B)
#
# Renders SCENE for FRAMES (default 7) --sync frames under callgrind, then
# again for one frame fewer, and prints the kernel's instructions (the JIT
# function lavapipe runs per SIMD row, with the texture functions it calls)
# for the whole run and for the last frame alone (the difference). lavapipe
# runs on two threads here so that the run is deterministic; the counts do
# not depend on the thread count. About a minute per run.
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:?usage: bench/kernel_instructions.sh SCENE [FRAMES]}
frames=${2:-7}
command -v valgrind >/dev/null || {
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq valgrind >/dev/null
}
px=${PX:-target/release/parallax}
[ -x "$px" ] || cargo build --release --locked 2>&1 | tail -n 3
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# The JIT code has no symbols: it is the function in no object file ([???])
# with the largest inclusive count.
kernel_ir() {
  callgrind_annotate --inclusive=yes "$1" 2>/dev/null |
    awk '/\?\?\?:0x[0-9a-f]+ \[\?\?\?\]$/ { gsub(",", "", $1); if ($1 + 0 > m) m = $1 + 0 } END { printf "%.0f", m }'
}

count() {
  LP_NUM_THREADS=2 valgrind --tool=callgrind --callgrind-out-file="$out/cg.$1" \
    "$px" render --scene "$scene" --sync --frames "$1" --out "$out/run.$1" >/dev/null 2>&1
  kernel_ir "$out/cg.$1"
}

all=$(count "$frames")
fewer=$(count $((frames - 1)))
awk -v a="$all" -v b="$fewer" -v f="$frames" -v s="$scene" 'BEGIN {
  printf "%s: kernel instructions, %d frames: %.1f M; the last frame: %.1f M\n", s, f, a / 1e6, (a - b) / 1e6
}'
