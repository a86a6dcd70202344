#!/usr/bin/env bash
# Soak: FRAMES frames (default 10,000) of a moving camera over a volume about
# 8× larger than the CPU and GPU brick budgets, under `mpirun -n 3` (one
# coordinator, two back ends), sampling every process's resident memory.
# Passes when the run ends cleanly and the back ends' RSS after warm-up stays
# flat. Not part of CI (it runs for a long time); run from the repository
# root:
#   bash bench/soak.sh [FRAMES]
# Figures: out/soak/summary.txt; samples: out/soak/rss.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh
cargo build --release --locked 2>&1 | tail -n 1
px=$PWD/target/release/parallax
frames=${1:-10000}
out=out/soak
rm -rf "$out" && mkdir -p "$out"

# 256³ shells, bricks of 32: 585 bricks, 109 MB decoded. Budgets 12 MiB
# each (CPU cache and GPU pool): the data is 8–9× larger than either.
$px synth shells --size 256 -o "$out/shells.nrrd" > /dev/null
$px import "$out/shells.nrrd" -o "$out/shells.pxo" --brick 32 > /dev/null
cat > "$out/tf.toml" <<'TF'
[[point]]
value = 0
color = [0, 0, 0]
extinction = 0
[[point]]
value = 100
color = [0.2, 0.5, 1.0]
extinction = 0.05
[[point]]
value = 255
color = [1.0, 0.8, 0.4]
extinction = 0.4
TF
$px display-gen --projectors 2 --resolution 96x54 --pixel-size 0.001 \
  --angular-accuracy 0.2 -o "$out/wall" > /dev/null
cat > "$out/scene.toml" <<'SC'
volume = "shells.pxo"
transfer_function = "tf.toml"
display = "wall/display.toml"
[placement]
center = [0, 0, 0]
size = 0.5
[render]
eta = 1.0
accuracy = 0.5
cpu_cache_mb = 12
gpu_cache_mb = 12
upload_budget = 16
SC
# The camera: keys every 100 frames, zooming (size 0.3–1.6, so the cut
# swings between coarse and as fine as the budgets allow), turning and
# panning, so bricks are evicted and read again all the time.
python3 - "$frames" > "$out/script.toml" <<'PY'
import math, sys
n = int(sys.argv[1])
print(f"frames = {n}")
for f in range(0, n, 100):
    t = f / 1000.0
    size = 0.3 + 1.3 * abs(math.sin(0.7 * t))
    cx, cy = 0.25 * math.sin(1.3 * t), 0.15 * math.cos(0.9 * t)
    print(f"[[key]]\nframe = {f}\nplacement = {{ center = [{cx:.4f}, {cy:.4f}, 0.0], "
          f"rotation_deg = [{20 * math.sin(t):.2f}, {(f * 0.9) % 360:.2f}, 0.0], size = {size:.4f} }}")
PY

mpirun -n 3 "$px" render --scene "$out/scene.toml" --script "$out/script.toml" \
  --out "$out/run" > "$out/run.log" 2>&1 &
launcher=$!
echo "seconds,pid,rss_kib" > "$out/rss.csv"
start=$(date +%s)
while kill -0 $launcher 2>/dev/null; do
  now=$(( $(date +%s) - start ))
  for pid in $(pgrep -f "^$px render --scene $out/scene.toml" || true); do
    rss=$(awk '/VmRSS/ {print $2}' /proc/$pid/status 2>/dev/null || true)
    [ -n "$rss" ] && echo "$now,$pid,$rss" >> "$out/rss.csv"
  done
  # Images are not what a soak keeps: drop the frame folders as they come.
  find "$out/run" -maxdepth 1 -name 'frame_*' -type d -mmin +0.2 -exec rm -rf {} + 2>/dev/null || true
  sleep 5
done
status=0
wait $launcher || status=$?
rm -rf "$out"/run/frame_*

python3 - "$out" "$status" <<'PY' | tee "$out/summary.txt"
import csv, json, sys, statistics
out, status = sys.argv[1], int(sys.argv[2])
stats = [json.loads(l) for l in open(f"{out}/run/stats.jsonl")]
frames = 1 + max(s["frame"] for s in stats)
errors = [s for s in stats if s.get("error")]
rows = list(csv.DictReader(open(f"{out}/rss.csv")))
by_pid = {}
for r in rows:
    by_pid.setdefault(r["pid"], []).append((int(r["seconds"]), int(r["rss_kib"])))
print(f"exit status {status}; {frames} frames; {len(errors)} frames with an error")
print(f"frame time median {statistics.median(s['total_ms'] for s in stats):.1f} ms; "
      f"bytes read {max(s['bytes_read'] for s in stats) / 1e6:.1f} MB in all; "
      f"uploads {sum(s['uploaded'] for s in stats)}")
print("process  RSS MiB: after warm-up (first 20% of samples dropped) first quarter median → last quarter median, max")
for pid, s in sorted(by_pid.items()):
    v = [kib for _, kib in s][len(s) // 5:]
    if len(v) < 8:
        continue
    q = len(v) // 4
    a, b = statistics.median(v[:q]) / 1024, statistics.median(v[-q:]) / 1024
    print(f"{pid:>7}  {a:8.1f} → {b:8.1f} ({100 * (b - a) / a:+.1f}%), max {max(v) / 1024:.1f}")
PY
exit $status
