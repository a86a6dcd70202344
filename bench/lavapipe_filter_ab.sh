#!/usr/bin/env bash
# lavapipe's two ways of filtering 8-bit bricks, A/B: its 8-bit integer path
# (GALLIVM_PERF empty, the driver's default) against its float path
# (GALLIVM_PERF=no_aos_sampling, what parallax asks for unless told
# otherwise), on four of bench/vtk_compare.sh's 8-bit partner scenes, in
# three alternating rounds; prints the median render_ms of frames 8-15 of
# each run. Needs what `bash bench/vtk_compare.sh` leaves in out/bench-vtk.
# Usage: bash bench/lavapipe_filter_ab.sh
set -euo pipefail
cd "$(dirname "$0")/.."
S=out/bench-vtk/scenes
out=out/lavapipe-filter-ab
scenes="ct-bone-ours-8-bit-2d-step0.5-etvtk ct-bone-ours-8-bit-b64-2d-step3.0-etvtk colin27-brain-ours-8-bit-b64-analytic-step1.5-etvtk colin27-skin-ours-8-bit-b64-analytic-step4.0-etvtk"
for sc in $scenes; do [ -f "$S/$sc.toml" ] || { echo "missing $S/$sc.toml: run bash bench/vtk_compare.sh first"; exit 1; }; done
for round in 1 2 3; do
  for sc in $scenes; do
    for mode in aos soa; do
      rm -rf "$out"
      if [ $mode = soa ]; then export GALLIVM_PERF=no_aos_sampling; else export GALLIVM_PERF=; fi
      target/release/parallax render --scene "$S/$sc.toml" --sync --frames 16 --out "$out" > /dev/null
      m=$(python3 -c "
import json, sys
L = [json.loads(l) for l in open(sys.argv[1])][8:]
v = sorted(x['render_ms'] for x in L)
print(round(v[len(v) // 2], 1))" "$out/stats.jsonl")
      echo "round $round $sc $([ $mode = soa ] && echo float || echo integer): $m ms"
    done
  done
done
