"""OME-Zarr images written by the ome-zarr and zarr Python packages (the
writers napari, Fiji exporters and microscopy pipelines use), for
tests/zarr.rs: Zarr v2 (NGFF 0.4) and v3 (NGFF 0.5), blosc, zstd and gzip,
sharding, a 3-level pyramid, channel and time axes; beside each chosen
volume the array itself as raw little-endian samples, and the damaged copies
the error tests read.

Usage: make_zarr.py OUT_DIR. The test command installs the packages in
target/py-zarr (scripts/test.sh).
"""

import json
import os
import shutil
import sys

import numcodecs
import numpy as np
import zarr
from ome_zarr.format import FormatV04, FormatV05
from ome_zarr.io import parse_url
from ome_zarr.writer import write_image
from zarr.codecs import BloscCodec, GzipCodec, ZstdCodec

out = sys.argv[1]
os.makedirs(out, exist_ok=True)

nz, ny, nx = 16, 20, 24
k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
# Two channels of a 16-bit image: distinct values everywhere, negative ones
# included, so a voxel read from the wrong place or channel shows.
ch0 = (i * 7 + j * 131 + k * 2017 - 15000).astype(np.int16)
ch1 = (i * j - k * 3 + 5).astype(np.int16)
czyx = np.stack([ch0, ch1])
SCALE = {"z": 2.5, "y": 0.5, "x": 0.75}
UNITS = {a: "micrometer" for a in "zyx"}
PYRAMID = [{"z": 2, "y": 2, "x": 2}, {"z": 4, "y": 4, "x": 4}]


def ome(name, image, axes, fmt, storage, scale=SCALE, pyramid=PYRAMID):
    path = os.path.join(out, name)
    store = parse_url(path, mode="w", fmt=fmt).store
    root = zarr.group(store=store, zarr_format=fmt.zarr_format)
    write_image(
        image,
        root,
        fmt=fmt,
        axes=axes,
        scale_factors=pyramid,
        scale=scale,
        axes_units=UNITS,
        storage_options=storage,
    )
    # The arrays themselves, for comparison: every level, channel (and
    # time point), as raw little-endian samples.
    for level in range(3):
        arr = zarr.open_array(os.path.join(path, f"s{level}"), mode="r")[...]
        lead = arr.shape[:-3]
        for idx in np.ndindex(*lead):
            tag = "".join(f".{a}{v}" for a, v in zip(axes[: len(lead)], idx))
            vol = arr[idx]
            vol.astype(vol.dtype.newbyteorder("<")).tofile(
                os.path.join(out, f"{name}.s{level}{tag}.raw")
            )
            with open(os.path.join(out, f"{name}.s{level}{tag}.json"), "w") as f:
                json.dump({"shape": list(vol.shape), "dtype": str(vol.dtype)}, f)


# Zarr v2, NGFF 0.4, blosc (lz4, byte shuffle): napari's and ome-zarr's
# long-time default.
ome(
    "v2-blosc.ome.zarr",
    czyx,
    "czyx",
    FormatV04(),
    dict(chunks=(1, 8, 10, 12), compressor=numcodecs.Blosc(cname="lz4", clevel=5, shuffle=1)),
)
# Zarr v2, NGFF 0.4, zstd.
ome(
    "v2-zstd.ome.zarr",
    czyx,
    "czyx",
    FormatV04(),
    dict(chunks=(1, 5, 7, 9), compressor=numcodecs.Zstd(level=3)),
)
# Zarr v3, NGFF 0.5, zstd.
ome(
    "v3-zstd.ome.zarr",
    czyx,
    "czyx",
    FormatV05(),
    dict(chunks=(1, 8, 10, 12), compressors=[ZstdCodec(level=3)]),
)
# Zarr v3, NGFF 0.5, sharded, blosc (zstd inside), 16-bit unsigned, with a
# time axis: chunks of 4³ inside shards of 8³.
tczyx = np.stack([czyx.astype(np.int32) + 20000, czyx.astype(np.int32) + 30000]).astype(np.uint16)
ome(
    "v3-sharded.ome.zarr",
    tczyx,
    "tczyx",
    FormatV05(),
    dict(
        chunks=(1, 1, 4, 4, 4),
        shards=(1, 1, 8, 8, 8),
        compressors=[BloscCodec(cname="zstd", clevel=3, shuffle="bitshuffle")],
    ),
)
# Zarr v3, gzip, float32: a light-sheet channel in physical units.
ome(
    "v3-gzip-f32.ome.zarr",
    (ch1.astype(np.float32) * 0.25)[None],
    "czyx",
    FormatV05(),
    dict(chunks=(1, 16, 20, 24), compressors=[GzipCodec(level=5)]),
)

# Thick slices with a pyramid halving only y and x, as the ome-zarr tools
# write by default and as Parallax's octree halves such voxels (1 × 1 × 4
# µm, then 2 × 2 × 4, then 4 × 4 × 4): the coarser levels import reuses.
tz, ty, tx = np.meshgrid(np.arange(16), np.arange(64), np.arange(64), indexing="ij")
thick = (tx * 37 + ty * 11 + tz * 301 + ((tx * ty + 3 * tz) % 23) * 97 - 9000).astype(np.int16)
ome(
    "pyramid.ome.zarr",
    thick,
    "zyx",
    FormatV05(),
    dict(chunks=(8, 16, 16), compressors=[ZstdCodec(level=3)]),
    scale={"z": 4.0, "y": 1.0, "x": 1.0},
    pyramid=[{"z": 1, "y": 2, "x": 2}, {"z": 1, "y": 4, "x": 4}],
)

# Damaged copies.
# A pyramid whose coarsest level lost its array metadata.
broken = os.path.join(out, "pyramid-broken.ome.zarr")
shutil.copytree(os.path.join(out, "pyramid.ome.zarr"), broken)
os.remove(os.path.join(broken, "s2", "zarr.json"))

src = os.path.join(out, "v3-zstd.ome.zarr")
chunk = os.path.join("s0", "c", "0", "1", "1", "0")

corrupt = os.path.join(out, "corrupt-chunk.ome.zarr")
shutil.copytree(src, corrupt)
with open(os.path.join(corrupt, chunk), "r+b") as f:
    data = bytearray(f.read())
    for n in range(4, len(data)):
        data[n] ^= 0x5A
    f.seek(0)
    f.write(data)

missing = os.path.join(out, "missing-chunk.ome.zarr")
shutil.copytree(src, missing)
os.remove(os.path.join(missing, chunk))

# Metadata that contradicts itself: a scale with three values for four axes.
bad = os.path.join(out, "inconsistent.ome.zarr")
shutil.copytree(os.path.join(out, "v2-blosc.ome.zarr"), bad)
with open(os.path.join(bad, ".zattrs")) as f:
    attrs = json.load(f)
attrs["multiscales"][0]["datasets"][0]["coordinateTransformations"][0]["scale"] = [2.5, 0.5, 0.75]
with open(os.path.join(bad, ".zattrs"), "w") as f:
    json.dump(attrs, f)

# Axes that do not match the array: three listed for four dimensions.
bad_axes = os.path.join(out, "axes-mismatch.ome.zarr")
shutil.copytree(os.path.join(out, "v3-zstd.ome.zarr"), bad_axes)
with open(os.path.join(bad_axes, "zarr.json")) as f:
    meta = json.load(f)
ms = meta["attributes"]["ome"]["multiscales"][0]
ms["axes"] = ms["axes"][1:]
for ds in ms["datasets"]:
    for t in ds["coordinateTransformations"]:
        t[t["type"]] = t[t["type"]][1:]
with open(os.path.join(bad_axes, "zarr.json"), "w") as f:
    json.dump(meta, f)

# A codec Parallax does not read: LZMA, a real numcodecs compressor.
ome(
    "lzma.ome.zarr",
    czyx,
    "czyx",
    FormatV04(),
    dict(chunks=(1, 8, 10, 12), compressor=numcodecs.LZMA()),
)
