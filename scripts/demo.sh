#!/usr/bin/env bash
# The demo: imports the Colin27 head MRI into the out-of-core octree database,
# then renders it on the desktop display with two transfer functions (opaque
# skin, translucent brain tissue), opened by a clip plane, and with MImDA;
# then on a 16-projector light field wall, where eyes at different places see
# different things (G10 §4); and a CT imported from an OME-Zarr image.
# Images land in out/demo/.
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

$px render --scene configs/scenes/colin27.toml --frames 8 --sync --out "$out/skin"
$px render --scene configs/scenes/colin27-brain.toml --frames 8 --sync --out "$out/brain"

cp "$out/skin/frame_00007/window.png" "$out/colin27-skin.png"
cp "$out/brain/frame_00007/window.png" "$out/colin27-brain.png"

# Tools and enhancers: a clip plane with an emphasis band, and MImDA.
$px render --scene configs/scenes/colin27-clip.toml --frames 8 --sync --out "$out/clip"
$px render --scene configs/scenes/colin27-probe.toml --frames 8 --sync --out "$out/probe"
$px render --scene configs/scenes/colin27-band.toml --frames 8 --sync --out "$out/band"
$px render --scene configs/scenes/colin27-shading.toml --frames 8 --sync --out "$out/shading"
$px render --scene configs/scenes/colin27-overlay.toml --frames 8 --sync --out "$out/overlay"
$px render --scene configs/scenes/colin27-mimda.toml --frames 8 --sync --out "$out/mimda"
$px render --scene configs/scenes/colin27-iso.toml --frames 8 --sync --out "$out/iso"
cp "$out/clip/frame_00007/window.png" "$out/colin27-clip.png"
cp "$out/probe/frame_00007/window.png" "$out/colin27-probe.png"
cp "$out/band/frame_00007/window.png" "$out/colin27-band.png"
cp "$out/shading/frame_00007/window.png" "$out/colin27-shading.png"
cp "$out/overlay/frame_00007/window.png" "$out/colin27-overlay.png"
cp "$out/mimda/frame_00007/window.png" "$out/colin27-mimda.png"
cp "$out/iso/frame_00007/window.png" "$out/colin27-iso.png"

# A registered layer: the skin of the same scan through its own transfer
# function, its media added to the brain tissue's.
$px render --scene configs/scenes/colin27-layers.toml --frames 8 --sync --out "$out/layers"
cp "$out/layers/frame_00007/window.png" "$out/colin27-layers.png"
# A label layer: tissue labels made of the scan by thresholds, each in its
# colour from an ITK-SNAP label description file, read at the nearest voxel.
$px import "$src" -o "$out/colin27-labels.pxo" --labels-from-thresholds 60,95,120
$px render --scene configs/scenes/colin27-labels.toml --frames 8 --sync --out "$out/labels"
cp "$out/labels/frame_00007/window.png" "$out/colin27-labels.png"

# OME-Zarr: the CT phantom written as an OME-Zarr image (NGFF 0.5, Zarr v3,
# 64³ zstd chunks), imported from it, rendered with the CT-Bone preset.
$px synth ct --size 192 --type i16 -o "$out/ct.ome.zarr"
$px import "$out/ct.ome.zarr" -o "$out/ct-zarr.pxo"
$px render --scene configs/scenes/ct-zarr.toml --frames 8 --sync --out "$out/ct-zarr"
cp "$out/ct-zarr/frame_00007/window.png" "$out/ct-zarr.png"

# The light field: a 16-projector wall (η = 1), and what five eyes along
# the viewing line see on it. `wall SCENE NAME` renders the wall's scene
# into $out/NAME and writes the eye sweep $out/NAME-eyes.png.
wall() {
  $px render --scene "configs/scenes/$1.toml" --frames 6 --sync --out "$out/$2"
  $px simulate --display configs/displays/wall16/display.toml --frames "$out/$2/frame_00005" \
    --eye=-0.3,0,2 --eye=0.3,0,2 --sweep 5 --resolution 320x180 -o "$out/$2-eyes.png"
}
wall colin27-wall wall16


# The view-dependent clip plane on the wall: eyes on the right look straight
# at the cut and see inside, eyes on the left look along it and the skin
# comes back.
wall colin27-wall-clip wall16-clip

# The context-preserving probe on the wall: eyes on the right look along its
# axis and keep the edges of the tissue it clears; from the left they are
# gone. The band picker likewise: the white matter alone on the right.
wall colin27-wall-probe wall16-probe
wall colin27-wall-band wall16-band

# Tool geometry on the wall: every projector draws the cursor and the
# probe's sphere where its rays through them leave it, so every eye sees
# them at the same place in space.
wall colin27-wall-overlay wall16-overlay

# A layer with view-dependent opacity on the wall: the skin for eyes on the
# left, the brain tissue for eyes on the right.
wall colin27-wall-layers wall16-layers

# A Looking Glass Portrait: its 48 views interleaved onto the panel's
# sub-pixels through the lenticular mapping of its calibration (the display
# in configs/displays/looking-glass-portrait/ was made from its visual.json
# by `parallax display-gen --looking-glass`).
$px render --scene configs/scenes/colin27-looking-glass.toml --frames 6 --sync --out "$out/looking-glass"
cp "$out/looking-glass/frame_00005/panel.png" "$out/looking-glass-panel.png"

echo
echo "Look at: $out/colin27-skin.png, $out/colin27-brain.png, $out/colin27-clip.png,"
echo "         $out/colin27-mimda.png, $out/colin27-iso.png, $out/wall16-eyes.png, $out/wall16-clip-eyes.png,"
echo "         $out/colin27-probe.png, $out/colin27-band.png, $out/colin27-shading.png, $out/wall16-probe-eyes.png, $out/wall16-band-eyes.png,"
echo "         $out/colin27-overlay.png, $out/wall16-overlay-eyes.png, $out/ct-zarr.png (from an OME-Zarr image),"
echo "         $out/colin27-layers.png, $out/wall16-layers-eyes.png (a registered layer, view-dependent on the wall),"
echo "         $out/colin27-labels.png (a label layer: tissue labels in their colours)"
echo "         and $out/looking-glass-panel.png (the panel of a Looking Glass, interleaved for its lenses)"
echo "(every frame: $out/skin/frame_*/window.png; figures per frame: $out/skin/stats.jsonl)"
