#!/usr/bin/env bash
# Brick compression: LZ4 against zstd levels 1–3, each with and without the
# delta pre-filter, on Colin27 (MRI, u8), a CT phantom (i16 Hounsfield units
# with scanner noise, mostly air) and a smooth simulation field
# (Marschner–Lobb, f32). Ratio to the source size, encode and decode speed on
# one thread. Then a cold-cache render of Colin27 from a .pxo written with
# LZ4 and one written with the default codec.
# Usage: bash bench/codecs.sh [SIZE]   (SIZE of the synthetic volumes, 256)
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
set +u
size="${1:-256}"
cargo build --release -q
bin=target/release/parallax
out=out/bench-codecs
mkdir -p "$out"
colin=/usr/share/mricron/templates/ch2.nii.gz
[ -f "$out/ct-$size.nrrd" ] || $bin synth ct --size "$size" --type i16 -o "$out/ct-$size.nrrd"
[ -f "$out/field-$size.nrrd" ] || $bin synth marschner-lobb --size "$size" --type f32 -o "$out/field-$size.nrrd"
for q in u8 u16; do
  echo "== bricks quantised to $q"
  $bin bench codecs "$colin,$out/ct-$size.nrrd,$out/field-$size.nrrd" --quantize "$q" --out "$out/$q"
done

echo "== cold-cache render of Colin27 (512x512 desktop view), LZ4 against the default codec"
for c in lz4 zstd1+auto; do
  $bin import "$colin" -o "$out/colin27-$c.pxo" --codec "$c" >/dev/null
  sed -e "s#^volume = .*#volume = \"colin27-$c.pxo\"#" \
      -e "s#^transfer_function = .*#transfer_function = \"$PWD/configs/tf/colin27-skin.toml\"#" \
      -e "s#^display = .*#display = \"$PWD/configs/displays/desktop.toml\"#" \
      configs/scenes/colin27.toml > "$out/colin27-$c.toml"
done
for round in 1 2 3; do
  for c in lz4 zstd1+auto; do
    sync; echo 3 > /proc/sys/vm/drop_caches 2>/dev/null || true
    start=$(date +%s.%N)
    $bin render --scene "$out/colin27-$c.toml" --out "$out/render-$c" >/dev/null 2>&1
    end=$(date +%s.%N)
    frames=$(wc -l < "$out/render-$c/stats.jsonl")
    printf '%-12s round %d: %.2f s to convergence, %d frames, file %d bytes\n' "$c" "$round" \
      "$(echo "$end - $start" | bc)" "$frames" "$(stat -c %s "$out/colin27-$c.pxo")"
  done
done
