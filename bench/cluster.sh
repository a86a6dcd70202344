#!/usr/bin/env bash
# Frame time of a 16-projector wall (configs/displays/wall16, 160×90 per
# projector, Colin27, η = 1) with 1, 2 and 4 back-end ranks, and the
# coordination cost with 5 ranks. Run from the repository root after
# `bash scripts/demo.sh` (which imports out/demo/colin27.pxo).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh
cargo build --release --locked 2>&1 | tail -n 1
px=target/release/parallax
[ -f out/demo/colin27.pxo ] || $px import /usr/share/mricron/templates/ch2.nii.gz -o out/demo/colin27.pxo --empty-below 10
out=out/bench-cluster
mkdir -p $out
for k in 1 2 4; do
  mpirun -n $((k + 1)) $px render --scene configs/scenes/colin27-wall.toml \
    --display configs/displays/wall16/display.toml --frames 12 --sync --out $out/ranks$k > $out/ranks$k.log 2>&1
done
python3 - "$out" <<'PY'
import json, sys, statistics
out = sys.argv[1]
print("backends  frame ms (median of the 6 converged last frames)  coordination ms  share  FrameState bytes  bricks/rank avg  max")
for k in (1, 2, 4):
    fr = [json.loads(l) for l in open(f"{out}/ranks{k}/frontend.jsonl")][-6:]
    st = [json.loads(l) for l in open(f"{out}/ranks{k}/stats.jsonl")]
    last = [s for s in st if s["frame"] == st[-1]["frame"]]
    wall = statistics.median(f["wall_ms"] for f in fr)
    coord = statistics.median(f["coordination_ms"] for f in fr)
    bricks = [s["cut_leaves_with_data"] for s in last]
    print(f"{k:8d}  {wall:10.1f}  {coord:15.2f}  {100*coord/wall:5.1f}%  {fr[-1]['state_bytes']:16d}  {sum(bricks)/len(bricks):15.0f}  {max(bricks)}")
PY
