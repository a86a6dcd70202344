#!/usr/bin/env bash
# Where lavapipe spends the ray-casting kernel's time, instruction by
# instruction: samples the CPU with perf while `parallax render` runs, dumps
# the code lavapipe compiled (it has no symbols: LLVM writes it into
# anonymous executable memory) with gdb from the running process, and
# annotates its disassembly with the share of samples at each instruction.
# Prints the share of each compiled function (the kernel, and the texture
# functions it calls: the brick pool's trilinear filter, the 2D
# pre-integration table, the textureLoad of the frame and slot tables),
# with its size, its vector gathers and its bounds-checked per-lane buffer
# loads (`vpminud`: lavapipe's way of reading a buffer at offsets it cannot
# prove uniform); the annotated listing is OUT/annot.txt.
#
#   bash bench/kernel_profile.sh SCENE [FRAMES] [OUT]
#   PX=/path/to/parallax bash bench/kernel_profile.sh SCENE   (another build)
#
# Run it on an otherwise idle machine; FRAMES (default 300) should keep the
# render going for well over DUMP_AFTER seconds (default 20), when the code
# is dumped. perf's samples land on the instruction after the one that
# stalled, so a gather that waits shows on the line below it.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh
scene=${1:?usage: bench/kernel_profile.sh SCENE [FRAMES] [OUT]}
frames=${2:-300}
out=${3:-out/kernel-profile}
px=${PX:-target/release/parallax}
[ -x "$px" ] || cargo build --release --locked 2>&1 | tail -n 3
for tool in perf gdb objdump; do
  command -v $tool >/dev/null || {
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq linux-perf gdb binutils >/dev/null
    break
  }
done
rm -rf "$out"
mkdir -p "$out"
perf record -F 4999 -e cpu-clock -o "$out/perf.data" -- \
  "$px" render --scene "$scene" --sync --frames "$frames" --out "$out/run" >"$out/render.log" 2>&1 &
rec=$!
sleep "${DUMP_AFTER:-20}"
pid=$(pgrep -P "$rec" | head -n 1)
[ -n "$pid" ] || { echo "the render ended before the dump: give more FRAMES" >&2; exit 1; }
# Anonymous executable mappings: what the JIT wrote.
awk '($2 == "r-xp" || $2 == "rwxp") && NF == 5 { print $1 }' "/proc/$pid/maps" >"$out/maps.txt"
args=()
while read -r range; do
  args+=(-ex "dump binary memory $out/jit_${range%-*}.bin 0x${range%-*} 0x${range#*-}")
done <"$out/maps.txt"
gdb -p "$pid" -batch "${args[@]}" >"$out/gdb.log" 2>&1
wait "$rec"
perf script -i "$out/perf.data" -F ip,dso 2>/dev/null | awk '/perf-[0-9]+\.map/ { print $1 }' |
  sort | uniq -c | sort -rn >"$out/ips.txt"
python3 - "$out" <<'EOF'
import glob, os, re, subprocess, sys
out = sys.argv[1]
hits = {}
for line in open(f"{out}/ips.txt"):
    c, a = line.split()
    hits[int(a, 16)] = int(c)
total = sum(hits.values())
if not total:
    sys.exit("no samples in compiled code")
# The dumped region that holds most samples is the kernel's.
best = None
for f in glob.glob(f"{out}/jit_*.bin"):
    base = int(os.path.basename(f)[4:-4], 16)
    n = sum(c for a, c in hits.items() if base <= a < base + os.path.getsize(f))
    if best is None or n > best[0]:
        best = (n, f, base)
n, path, base = best
asm = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"--adjust-vma={base:#x}", path],
                     capture_output=True, text=True, check=True).stdout
insns = []
for line in asm.splitlines():
    m = re.match(r"\s*([0-9a-f]+):\s+(?:[0-9a-f]{2} )+\s*(.*)", line)
    if m:
        insns.append((int(m.group(1), 16), m.group(2)))
with open(f"{out}/annot.txt", "w") as f:
    for a, t in insns:
        f.write(f"{100 * hits.get(a, 0) / total:6.2f} {a:x}: {t}\n")
print(f"{total} samples in compiled code, {100 * n / total:.1f} % of them in the dumped region")
print("   share  instructions  gathers  per-lane loads  function")
funcs, body = [], []
for a, t in insns:
    if not body and (t.startswith(("nop", "data16", "cs ", "xchg")) or t == "(bad)"):
        continue
    body.append((a, t))
    if t.startswith("ret"):
        funcs.append(body)
        body = []
for b in funcs:
    share = 100 * sum(hits.get(a, 0) for a, _ in b) / total
    if share >= 0.2:
        gathers = sum("gather" in t for _, t in b)
        loads = sum("vpminud" in t for _, t in b)
        print(f"  {share:5.1f} %  {len(b):12d}  {gathers:7d}  {loads:14d}  {b[0][0]:#x}")
print(f"annotated listing: {out}/annot.txt")
EOF
