#!/usr/bin/env bash
# Import throughput at every size (issue 39): the CT phantom (`parallax synth
# ct`, 16-bit Hounsfield units with scanner noise, mostly air) written as NRRD
# and as OME-Zarr (NGFF 0.5, Zarr v3, 64³ zstd chunks), then imported with the
# defaults and a memory budget; MB/s of source and peak resident memory.
#
#   bash bench/import_throughput.sh [SIZES] [MEMORY_MB]    (default "512 1024 2048" 2048)
#
# The page cache: each file is imported right after it was written, twice up
# to 1024³ (the second import's figure is reported: read from the page
# cache) and once above (a 2048³ file does not fit in 24 GiB: what the
# cache does not hold is read from disk); `free -g` is printed beside. Needs
# about 2.3 × 16·N³ bytes of disk for the largest N. Writes
# out/bench-import/import.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
SIZES=${1:-"512 1024 2048"}
MEM=${2:-2048}
cargo build --release --locked 2>&1 | tail -n 1
px=$PWD/target/release/parallax
out=out/bench-import
mkdir -p "$out"
csv=$out/import.csv
echo "size,format,source_mb,seconds,mb_per_s,peak_rss_mib,memory_mb" > "$csv"
for n in $SIZES; do
  for fmt in nrrd ome.zarr; do
    src=$out/ct$n.$fmt
    [ -e "$src" ] || $px synth ct --size "$n" --type i16 -o "$src" >/dev/null
    # Twice where the file fits in the page cache (the second run is
    # reported), once above 1024³ (it does not fit: read from disk as much as
    # from the cache).
    runs=2; [ "$n" -gt 1024 ] && runs=1
    for run in $(seq $runs); do
      line=$( { /usr/bin/time -f "rss %M" $px import "$src" -o "$out/ct$n.pxo" --memory-mb "$MEM" 2>&1; } | grep -E "^imported|^rss")
    done
    secs=$(echo "$line" | sed -n 's/.* in \([0-9.]*\) s .*/\1/p')
    mbs=$(echo "$line" | sed -n 's/.*s (\([0-9]*\) MB\/s.*/\1/p')
    srcmb=$(echo "$line" | sed -n 's/.*: [0-9]* nodes .*), \([0-9.]*\) MB → .*/\1/p')
    rss=$(echo "$line" | sed -n 's/^rss \([0-9]*\)/\1/p')
    rss_mib=$(awk -v k="$rss" 'BEGIN { printf "%.0f", k / 1024 }')
    echo "$n,$fmt,$srcmb,$secs,$mbs,$rss_mib,$MEM" | tee -a "$csv"
    rm -f "$out/ct$n.pxo"
  done
  free -g | sed -n 2p
  rm -rf "$out/ct$n.nrrd" "$out/ct$n.ome.zarr"
done
