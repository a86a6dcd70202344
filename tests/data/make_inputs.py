#!/usr/bin/python3
"""Writes the test inputs that independent tools produce: DICOM series
(pydicom) and TIFF stacks (tifffile) of one CT-like volume, which is also
written as a plain NRRD so the project's own reader gives the reference.

Usage: make_inputs.py OUT_DIR

OUT_DIR/
  ct.nrrd                 int16 Hounsfield units, 0.7 × 0.6 × 1.5 mm
  dicom/                  the volume as a CT series: uint16 + RescaleIntercept
                          −1024, files named in shuffled order
  dicom-rle/              the same series, RLE lossless
  dicom-two/              two series in one folder
  dicom-missing/          the series with one slice removed
  dicom-uneven/           the series with one slice moved by 0.4 mm
  dicom-tilt/             the series with a 2° gantry tilt tag
  dicom-j2k/              one slice claiming JPEG 2000 (not decoded here)
  tiff/                   one 2-D int16 TIFF per slice, natural-order names
  stack.tif               one multi-page uint16 TIFF with ImageJ metadata
  stack-f32.tif           one multi-page float32 TIFF
  crafted/                hostile headers (issue 38): NIfTI sizes of 32767³
                          f64 in 416 bytes (plain and gzip), a negative
                          dim, a vox_offset of 3e38; a TIFF 2^32 − 1 wide
                          and one whose IFD list loops; a DICOM claiming
                          65535² × 2^31 frames
"""
import os
import gzip
import random
import struct
import shutil
import sys

import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileDataset, FileMetaDataset
from pydicom.uid import (ExplicitVRLittleEndian, RLELossless,
                         JPEG2000Lossless, generate_uid, CTImageStorage)
import tifffile

NX, NY, NZ = 24, 20, 16
SPACING = (0.7, 0.6, 1.5)  # x (between columns), y (between rows), z


def volume():
    z, y, x = np.mgrid[0:NZ, 0:NY, 0:NX]
    cx, cy, cz = (NX - 1) / 2, (NY - 1) / 2, (NZ - 1) / 2
    r = np.sqrt(((x - cx) * SPACING[0]) ** 2 + ((y - cy) * SPACING[1]) ** 2
                + ((z - cz) * SPACING[2]) ** 2)
    hu = np.where(r < 6.0, 40, -1000)
    hu = np.where((r > 4.5) & (r < 6.0), 1000, hu)
    rng = np.random.default_rng(7)
    hu = hu + rng.integers(-20, 21, size=hu.shape)
    hu[0, 0, 0] = -1024  # the stored minimum
    hu[-1, -1, -1] = 3071  # and maximum
    return hu.astype(np.int16)  # (z, y, x)


def write_nrrd(path, vol):
    header = ("NRRD0004\ntype: int16\ndimension: 3\nsizes: %d %d %d\n"
              "spacings: %r %r %r\nendian: little\nencoding: raw\n\n"
              % (NX, NY, NZ, SPACING[0], SPACING[1], SPACING[2]))
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(vol.astype("<i2").tobytes())


def slice_dataset(folder, name, series_uid, description, number, shape,
                  orientation, position, bits_stored):
    """One CT slice's dataset: the fields every series here shares."""
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(os.path.join(folder, name), {}, file_meta=meta,
                     preamble=b"\0" * 128)
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.8.498.1"
    ds.SeriesInstanceUID = series_uid
    ds.SeriesDescription = description
    ds.Modality = "CT"
    ds.InstanceNumber = number
    ds.Rows, ds.Columns = shape
    ds.PixelSpacing = [SPACING[1], SPACING[0]]  # row spacing, column spacing
    ds.SliceThickness = SPACING[2]
    ds.ImageOrientationPatient = orientation
    ds.ImagePositionPatient = position
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated = 16
    ds.BitsStored = bits_stored
    ds.HighBit = bits_stored - 1
    ds.PixelRepresentation = 0
    ds.is_little_endian = True
    ds.is_implicit_VR = False
    return ds


def write_series(folder, vol, series_uid, description, z_positions,
                 syntax=ExplicitVRLittleEndian, tilt=None, names=None):
    os.makedirs(folder, exist_ok=True)
    order = list(range(len(z_positions)))
    random.Random(3).shuffle(order)
    for n, k in enumerate(order):
        name = names[k] if names else "IM%04d" % n
        ds = slice_dataset(folder, name, series_uid, description, k + 1, (NY, NX),
                           [1, 0, 0, 0, 1, 0], [-10.0, 20.0, z_positions[k]], 12)
        ds.RescaleIntercept = -1024
        ds.RescaleSlope = 1
        if tilt is not None:
            ds.GantryDetectorTilt = tilt
        stored = (vol[min(k, vol.shape[0] - 1)].astype(np.int32) + 1024).astype(np.uint16)
        ds.PixelData = stored.tobytes()
        if syntax == RLELossless:
            ds.compress(RLELossless, stored)
        elif syntax != ExplicitVRLittleEndian:
            ds.file_meta.TransferSyntaxUID = syntax
            ds.PixelData = pydicom.encaps.encapsulate([b"\xff\x4f\xff\x51not a codestream"])
        ds.save_as(os.path.join(folder, name), write_like_original=False)


def write_seg(folder, vol):
    """A label series made on the CT `vol` by thresholds (1 from -500 HU, 2
    from 500 HU: what `parallax import --labels-from-thresholds -500,500`
    makes of the CT), on another grid: cropped to columns 1..23 and slices
    2..15, its rows running to -x (ImageOrientationPatient [-1, 0, 0, 0, 1,
    0], so its slice normal is -z and its slices are ordered from the top),
    placed by its ImagePositionPatient where those voxels lie in the CT."""
    os.makedirs(folder, exist_ok=True)
    labels = (vol >= -500).astype(np.uint16) + (vol >= 500).astype(np.uint16)
    k0, k1, i0, i1 = 2, 16, 1, 24
    seg = labels[k0:k1, :, i0:i1][:, :, ::-1]  # column 0 is CT column i1 - 1
    for n in range(seg.shape[0]):
        position = [-10.0 + (i1 - 1) * SPACING[0], 20.0, 100.0 + (k0 + n) * SPACING[2]]
        ds = slice_dataset(folder, "SEG%04d" % n, "1.2.826.0.1.3680043.8.498.20",
                           "labels", n + 1, seg.shape[1:], [-1, 0, 0, 0, 1, 0],
                           position, 16)
        ds.PixelData = np.ascontiguousarray(seg[n]).tobytes()
        ds.save_as(os.path.join(folder, "SEG%04d" % n), write_like_original=False)


def nifti(dims, datatype=64, bitpix=64, vox_offset=352.0):
    """A NIfTI-1 header of `dims` (signed 16-bit, as the format has them)
    and 68 bytes of data: far fewer than the header claims."""
    h = bytearray(348)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, len(dims), *dims, *([1] * (7 - len(dims))))
    struct.pack_into("<hh", h, 70, datatype, bitpix)
    struct.pack_into("<8f", h, 76, *([1.0] * 8))
    struct.pack_into("<ff", h, 108, vox_offset, 1.0)
    h[344:348] = b"n+1\0"
    return bytes(h) + bytes(4 + 64)


def tiff(width, length, loop=False):
    """A little-endian TIFF of one 8-bit strip whose IFD says `width` ×
    `length` (LONG), and whose next-IFD offset points back at itself if
    `loop`."""
    entries = [(256, 4, width), (257, 4, length), (258, 3, 8), (259, 3, 1),
               (262, 3, 1), (273, 4, 200), (277, 3, 1), (279, 4, 16)]
    b = bytearray(b"II*\0" + struct.pack("<IH", 8, len(entries)))
    for tag, typ, val in entries:
        b += struct.pack("<HHII", tag, typ, 1, val)
    b += struct.pack("<I", 8 if loop else 0)
    return bytes(b) + bytes(216 - len(b))


def write_crafted(out):
    os.makedirs(out)
    huge = nifti([32767, 32767, 32767])
    for name, data in [("huge.nii", huge), ("huge.nii.gz", gzip.compress(huge)),
                       ("negative.nii", nifti([-5, 4, 4], 2, 8)),
                       ("offset.nii", nifti([4, 4, 4], 2, 8, 3.0e38)),
                       ("huge.tif", tiff(0xFFFFFFFF, 1)),
                       ("loop.tif", tiff(4, 4, loop=True))]:
        with open(os.path.join(out, name), "wb") as f:
            f.write(data)
    d = os.path.join(out, "dicom-huge")
    os.makedirs(d)
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(os.path.join(d, "a.dcm"), {}, file_meta=meta, preamble=bytes(128))
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.Modality = "CT"
    ds.SeriesInstanceUID = "1.2.826.0.1.3680043.8.498.12"
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.8.498.13"
    ds.Rows, ds.Columns, ds.NumberOfFrames = 65535, 65535, "2147483647"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 16, 15
    ds.PixelRepresentation, ds.SamplesPerPixel = 0, 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.PixelSpacing, ds.SliceThickness = [1, 1], 1
    ds.ImagePositionPatient, ds.ImageOrientationPatient = [0, 0, 0], [1, 0, 0, 0, 1, 0]
    ds.PixelData = bytes(16)
    ds.is_little_endian, ds.is_implicit_VR = True, False
    ds.save_as(os.path.join(d, "a.dcm"), write_like_original=False)


def main():
    out = sys.argv[1]
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    vol = volume()
    write_nrrd(os.path.join(out, "ct.nrrd"), vol)
    z = [100.0 + k * SPACING[2] for k in range(NZ)]
    uid = "1.2.826.0.1.3680043.8.498.10"
    write_series(os.path.join(out, "dicom"), vol, uid, "head 1.5 mm", z)
    write_series(os.path.join(out, "dicom-rle"), vol, uid, "head RLE", z, syntax=RLELossless)
    two = os.path.join(out, "dicom-two")
    write_series(two, vol, uid, "head 1.5 mm", z, names=["a%02d" % k for k in range(NZ)])
    write_series(two, vol[:4], "1.2.826.0.1.3680043.8.498.11", "scout", z[:4],
                 names=["b%02d" % k for k in range(4)])
    missing = z[:7] + z[8:]
    write_series(os.path.join(out, "dicom-missing"), np.delete(vol, 7, axis=0), uid, "gap", missing)
    uneven = list(z)
    uneven[9] += 0.4
    write_series(os.path.join(out, "dicom-uneven"), vol, uid, "uneven", uneven)
    write_series(os.path.join(out, "dicom-tilt"), vol, uid, "tilt", z, tilt=2.0)
    write_series(os.path.join(out, "dicom-j2k"), vol[:2], uid, "j2k", z[:2], syntax=JPEG2000Lossless)
    write_seg(os.path.join(out, "dicom-seg"), vol)

    tdir = os.path.join(out, "tiff")
    os.makedirs(tdir)
    for k in range(NZ):  # slice2 must come before slice10
        tifffile.imwrite(os.path.join(tdir, "slice%d.tif" % k), vol[k])
    u16 = (vol.astype(np.int32) + 1024).astype(np.uint16)
    tifffile.imwrite(os.path.join(out, "stack.tif"), u16, imagej=True,
                     resolution=(1 / SPACING[0], 1 / SPACING[1]),
                     metadata={"spacing": SPACING[2], "unit": "mm"})
    tifffile.imwrite(os.path.join(out, "stack-f32.tif"), vol.astype(np.float32) / 7.0)
    write_crafted(os.path.join(out, "crafted"))


if __name__ == "__main__":
    main()
