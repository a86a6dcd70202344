#!/bin/bash
# Writes the fuzzers' seed corpora (fuzz/corpus/<target>/): small real files
# of every format and encoding the parsers read, made by the project's own
# writers (`parallax synth`, `parallax import`), by independent ones (pydicom
# and tifffile through tests/data/make_inputs.py) and by hand, plus the wire
# messages `cargo test --test fuzz` encodes (PARALLAX_WRITE_SEEDS=1).
# Run from the repository root after `cargo build --release`; the corpora
# are committed, so this is needed only when a format grows.
set -euo pipefail
P=target/release/parallax
C=fuzz/corpus
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
rm -rf "$C"
mkdir -p "$C"/{nrrd,nhdr,nifti,raw,dicom,tiff,pxo,toml,preset,live,wire}

/usr/bin/python3 - "$C" <<'PY'
import bz2, gzip, json, os, struct, sys
C = sys.argv[1]
def w(t, name, data):
    with open(os.path.join(C, t, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())
vals = bytes((i * 37) % 256 for i in range(4 * 3 * 2))
head = "NRRD0004\ntype: %s\ndimension: 3\nsizes: 4 3 2\nspacings: 0.5 0.7 1.5\nencoding: %s\n%s\n"
w("nrrd", "raw-u8.nrrd", (head % ("uint8", "raw", "")).encode() + vals)
w("nrrd", "gzip-u8.nrrd", (head % ("uint8", "gzip", "")).encode() + gzip.compress(vals))
w("nrrd", "bzip2-u8.nrrd", (head % ("uint8", "bzip2", "")).encode() + bz2.compress(vals))
w("nrrd", "hex-u8.nrrd", (head % ("uint8", "hex", "")).encode() + vals.hex().encode())
w("nrrd", "ascii-f32.nrrd", (head % ("float", "ascii", "")).encode() + " ".join("%.2f" % (v / 3) for v in vals).encode())
i16 = b"".join(struct.pack(">h", v * 40 - 1000) for v in vals)
w("nrrd", "raw-i16-big.nrrd", (head % ("short", "raw", "endian: big\nspace directions: (0.5,0,0) (0,0.7,0) (0,0,1.5)\nspace: left-posterior-superior\n")).encode() + i16)
w("nrrd", "lineskip.nrrd", (head % ("uint8", "raw", "line skip: 0\nbyte skip: -1\n")).encode() + vals)
nh = "NRRD0004\ntype: %s\ndimension: 3\nsizes: %s\nspacings: 1 1 2\nencoding: raw\n%s"
w("nhdr", "detached.nhdr", nh % ("uint8", "16 16 16", "data file: d.raw\n"))
w("nhdr", "skip.nhdr", nh % ("uint16", "8 8 4", "byte skip: 1024\nendian: little\ndata file: d.raw\n"))
w("nhdr", "list.nhdr", nh % ("uint8", "16 16 2", "data file: LIST\nd.raw\nd.raw\n"))
w("nhdr", "pattern.nhdr", nh % ("uint8", "16 16 2", "data file: d.%s 0 1 1\n"))
def nifti(dims, datatype, bitpix, data, slope=0.0, inter=0.0):
    h = bytearray(348)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, 3, *dims, 1, 1, 1, 1)
    struct.pack_into("<hh", h, 70, datatype, bitpix)
    struct.pack_into("<8f", h, 76, 1, 0.5, 0.7, 1.5, 1, 1, 1, 1)
    struct.pack_into("<fff", h, 108, 352.0, slope, inter)
    h[344:348] = b"n+1\0"
    return bytes(h) + bytes(4) + data
w("nifti", "u8.nii", nifti((4, 3, 2), 2, 8, vals))
w("nifti", "i16-scaled.nii", nifti((4, 3, 2), 4, 16, b"".join(struct.pack("<h", v * 10 - 500) for v in vals), 0.5, -10))
w("nifti", "f32.nii", nifti((4, 3, 2), 16, 32, b"".join(struct.pack("<f", v / 7) for v in vals)))
w("raw", "u8", bytes([3, 2, 1, 0, 64, 0, 0, 0]) + vals)
w("raw", "i16-big", bytes([3, 2, 1, 2, 0, 0, 1, 0]) + i16)
w("raw", "f32-nan", bytes([1, 1, 0, 3, 0, 4, 0, 1]) + bytes(4) + struct.pack("<4f", 1, float("nan"), 2, 3))
for i, name in enumerate(["colin27-brain", "ct-bone", "mr-default"]):
    w("toml", "tf-" + name, b"\0" + open("configs/tf/%s.toml" % name, "rb").read())
w("toml", "display", b"\1" + open("configs/displays/desktop.toml", "rb").read())
w("toml", "projector", b"\2id = \"left\"\nposition = [-0.05, 0, 0.8]\nresolution = [32, 24]\nrank = 1\n")
for name in ["colin27-probe", "colin27-band", "colin27-overlay", "colin27-wall-shading"]:
    w("toml", "scene-" + name, b"\3" + open("configs/scenes/%s.toml" % name, "rb").read())
w("toml", "script-turntable", b"\4" + open("configs/scripts/turntable.toml", "rb").read())
w("preset", "slicer.xml", '<?xml version="1.0" encoding="UTF-8"?>\n<MRML>\n  <VolumeProperty name="CT-Bone" gradientOpacity="4 0 1 255 1" scalarOpacity="8 -3024 0 -16.4458 0 641.385 0.715686 3071 0.705882" colorTransfer="16 -3024 0 0 0 -16.4458 0.729412 0.254902 0.301961 641.385 0.905882 0.815686 0.552941 3071 1 1 1" interpolation="1" effectiveRange="-16.4458 641.385"/>\n</MRML>\n')
w("preset", "paraview.json", '[{"ColorSpace": "Diverging", "Name": "Cool to Warm", "Points": [0, 0, 0.5, 0, 100, 0.2, 0.5, 0, 255, 1, 0.5, 0], "RGBPoints": [0, 0.23, 0.29, 0.75, 127.5, 0.86, 0.86, 0.86, 255, 0.7, 0.01, 0.15]}]')
w("preset", "slicer.vp", "1\n0\n1\n8 -3024 0 -16.4458 0 641.385 0.715686 3071 0.705882\n4 0 1 255 1\n16 -3024 0 0 0 -16.4458 0.729412 0.254902 0.301961 641.385 0.905882 0.815686 0.552941 3071 1 1 1\n")
for i, m in enumerate([
    {"type": "rotate", "dx": 10, "dy": -5}, {"type": "zoom", "factor": 1.2},
    {"type": "pan", "dx": 0.01, "dy": -0.02}, {"type": "set", "eta": 0.5, "gamma": 0.3, "accuracy": 2, "step_factor": 0.5},
    {"type": "tf", "point": [{"value": 0, "color": [0, 0, 0], "extinction": 0}, {"value": 200, "color": [1, 1, 1], "extinction": 3, "importance": 0.5}]},
    {"type": "add-tool", "tool": {"kind": "probe", "center": [0, 0, 0], "radius": 0.05}},
    {"type": "tool", "index": 0, "band": [1, 2, 3, 4]}, {"type": "move-tool", "from": 0, "to": 0},
    {"type": "remove-tool", "index": 0}, {"type": "cursor", "point": [0.01, 0.02, 0.0]},
    {"type": "focus", "x": 0.5, "y": 0.5}, {"type": "grow-band", "index": 0, "x": 0.5, "y": 0.5, "tolerance": 0.1},
    {"type": "record", "on": True}, {"type": "output", "output": "eye"}, {"type": "quit"}]):
    w("live", "%02d-%s.json" % (i, m["type"]), json.dumps(m))
PY

# Volumes by the project's writer and importer.
$P synth shells --size 12 --type u16 -o "$T/shells.nrrd" >/dev/null
cp "$T/shells.nrrd" "$C/nrrd/synth-shells-u16.nrrd"
$P synth noise --size 16 -o "$T/noise.nrrd" >/dev/null
$P import "$T/noise.nrrd" -o "$C/pxo/noise-u8.pxo" --brick 8 >/dev/null
$P import "$T/shells.nrrd" -o "$C/pxo/shells-u16.pxo" --brick 4 >/dev/null
# DICOM and TIFF by pydicom and tifffile.
/usr/bin/python3 tests/data/make_inputs.py "$T/inputs" >/dev/null
cp "$T/inputs/dicom/$(ls "$T/inputs/dicom" | head -1)" "$C/dicom/ct-slice.dcm"
cp "$T/inputs/dicom-rle/$(ls "$T/inputs/dicom-rle" | head -1)" "$C/dicom/ct-rle.dcm"
cp "$T/inputs/dicom-j2k/$(ls "$T/inputs/dicom-j2k" | head -1)" "$C/dicom/j2k.dcm"
cp "$T/inputs/tiff/slice0.tif" "$C/tiff/slice-i16.tif"
cp "$T/inputs/stack.tif" "$C/tiff/imagej-u16.tif"
cp "$T/inputs/stack-f32.tif" "$C/tiff/f32.tif"
# The wire messages, encoded by the protocol as it stands.
PARALLAX_WRITE_SEEDS=1 cargo test --release --test fuzz wire_seeds -q >/dev/null
du -sh "$C"/*
