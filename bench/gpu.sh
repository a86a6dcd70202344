#!/usr/bin/env bash
# The frame-rate sequence of G10 §7 ("Standard desktop rendering": a
# 1024×576 window, 1 voxel per pixel) on whatever adapter is present: Colin27
# turned 1° per frame by configs/scripts/rotate-1deg.toml, with the opaque
# skin and the translucent brain transfer functions, plain and with frame
# reconstruction; then `parallax bench` (error against time per knob) at the
# same size. Prints the adapter chosen and the median frame rate of each run,
# beside G10's 23–60 Hz (opaque) and 11–39 Hz (transparent) on a GTX 280.
# Meant for a machine with a GPU; on lavapipe give a smaller size.
# Usage: bash bench/gpu.sh [WxH] [FRAMES]   (default 1024x576 60)
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
size="${1:-1024x576}"
frames="${2:-60}"
w="${size%x*}"; h="${size#*x}"
cargo build --release -q
bin=target/release/parallax
out=out/bench-gpu
mkdir -p "$out/display/projectors"
colin=/usr/share/mricron/templates/ch2.nii.gz
[ -f "$out/colin27.pxo" ] || $bin import "$colin" -o "$out/colin27.pxo" >/dev/null
# A 16:9 window, 0.4 m wide, the eye 80 cm away.
pixel=$(awk -v w="$w" 'BEGIN { printf "%.10f", 0.4 / w }')
height=$(awk -v w="$w" -v h="$h" 'BEGIN { printf "%.10f", 0.4 * h / w }')
cat > "$out/display/display.toml" <<TOML
[screen]
size = [0.4, $height]
pixel_size = $pixel
angular_accuracy_deg = 0.0
[observer]
position = [0.0, 0.0, 0.8]
projectors = "projectors/"
TOML
printf 'id = "window"\nposition = [0.0, 0.0, 0.8]\nresolution = [%s, %s]\n' "$w" "$h" \
  > "$out/display/projectors/window.toml"
RUST_LOG=info $bin render --scene configs/scenes/colin27.toml --display "$out/display/display.toml" \
  --frames 1 --out "$out/probe" 2>&1 | grep -m1 "GPU adapter chosen" || true
for tf in skin brain; do
  for recon in false true; do
    name="$tf-recon-$recon"
    sed -e "s#^volume = .*#volume = \"$PWD/$out/colin27.pxo\"#" \
        -e "s#^transfer_function = .*#transfer_function = \"$PWD/configs/tf/colin27-$tf.toml\"#" \
        -e "s#^display = .*#display = \"$PWD/$out/display/display.toml\"#" \
        -e "s#^accuracy = .*#accuracy = 1.0#" \
        -e "s#^\[render\]#[render]\nreconstruction = $recon#" \
        configs/scenes/colin27.toml > "$out/$name.toml"
    rm -rf "${out:?}/$name"
    $bin render --scene "$out/$name.toml" --script configs/scripts/rotate-1deg.toml \
      --frames "$frames" --out "$out/$name" >/dev/null
    # Median over the second half of the frames (the cut has settled).
    med=$(awk -F'"wall_ms":' 'NF > 1 { split($2, a, /[,}]/); print a[1] }' "$out/$name/frontend.jsonl" \
      | tail -n $(( frames / 2 )) | sort -g | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }')
    printf '%-6s reconstruction %-5s: median %8.1f ms/frame = %6.1f Hz\n' "$tf" "$recon" "$med" \
      "$(echo "scale=2; 1000 / $med" | bc)"
  done
done
echo "G10 (GTX 280, 1024×576, 1 voxel/pixel): opaque 23–60 Hz, transparent 11–39 Hz"
$bin bench --size "$size" --out "$out/bench" | tail -n 2
