"""VTK's side of bench/vtk_compare.py: the Colin27 volume read through
VTK and checked against the file's bytes, vtkFixedPointVolumeRayCastMapper
set up to compute Parallax's integral on the same view, and its timed
renders."""

import ctypes
import math
import re
import statistics
import struct
from pathlib import Path

import numpy as np

from bench_common import Meter, log, tf_at, wait_idle

VOLUME = Path("/usr/share/mricron/templates/ch2.nii.gz")
W = H = 512
SCREEN = (0.3, 0.3)          # m, centred on the origin, z = 0
EYE = np.array([0.0, 0.0, 0.8])

# --------------------------------------------------------------------------
# VTK.

def vtk_read_volume():
    """ch2.nii.gz through vtkNIFTIImageReader, checked against the file's own
    bytes: the voxels must come in raw file order (x fastest), as Parallax
    reads them (it ignores qform/sform)."""
    import gzip

    import vtk
    from vtk.util import numpy_support as ns

    reader = vtk.vtkNIFTIImageReader()
    reader.SetFileName(str(VOLUME))
    reader.Update()
    img = reader.GetOutput()
    dims = img.GetDimensions()
    spacing = img.GetSpacing()
    arr = ns.vtk_to_numpy(img.GetPointData().GetScalars())

    raw = gzip.open(VOLUME).read()
    ndim = struct.unpack("<8h", raw[40:56])
    datatype = struct.unpack("<h", raw[70:72])[0]
    vox_offset = int(struct.unpack("<f", raw[108:112])[0])
    slope, inter = struct.unpack("<2f", raw[112:120])
    assert datatype == 2, f"expected u8 NIfTI (datatype 2), got {datatype}"
    n = ndim[1] * ndim[2] * ndim[3]
    fileorder = np.frombuffer(raw[vox_offset:vox_offset + n], dtype=np.uint8)
    assert tuple(dims) == tuple(ndim[1:4]), (dims, ndim)
    assert np.array_equal(arr, fileorder), "vtkNIFTIImageReader reordered the voxels"
    assert slope in (0.0, 1.0) and inter == 0.0, (slope, inter)
    assert img.GetScalarTypeAsString() == "unsigned char"
    m = img.GetDirectionMatrix()
    assert all(m.GetElement(i, j) == (1.0 if i == j else 0.0) for i in range(3) for j in range(3))
    return reader, dims, spacing, arr.reshape(dims[2], dims[1], dims[0])


def read_nrrd(path):
    """The raw little-endian NRRD `parallax synth` writes: (None, dims,
    spacing, array z, y, x)."""
    data = Path(path).read_bytes()
    end = data.index(b"\n\n")
    fields = {}
    for line in data[:end].decode().splitlines()[1:]:
        if line.startswith("#") or ":" not in line:
            continue
        k, v = line.split(":", 1)
        fields[k.strip()] = v.strip()
    assert fields["encoding"] == "raw" and fields.get("endian", "little") == "little", fields
    types = {"short": "<i2", "signed short": "<i2", "int16": "<i2", "unsigned char": "u1", "uchar": "u1",
             "ushort": "<u2", "unsigned short": "<u2", "uint8": "u1", "uint16": "<u2"}
    dtype = np.dtype(types[fields["type"]])
    dims = tuple(int(x) for x in fields["sizes"].split())
    spacing = (1.0, 1.0, 1.0)
    if "spacings" in fields:
        spacing = tuple(float(x) for x in fields["spacings"].split())
    arr = np.frombuffer(data[end + 2:], dtype=dtype, count=dims[0] * dims[1] * dims[2])
    return None, dims, spacing, arr.reshape(dims[2], dims[1], dims[0])


def vtk_setup(tf, placement, threads, domain, volume):
    """One VTK pipeline. domain:
    "box"     — Parallax's domain: the field clamped to the edge voxels inside
                [0, N·s] (docs/design.md "Volume space"). The volume is padded with
                one replicated voxel on every side (so trilinear interpolation
                is the clamped field out to the box) and cropped to the box
                with the mapper's cropping planes.
    "centres" — VTK as it comes: the volume ends at the outer voxel centres
                [½s, (N−½)s], half a voxel short of the box on every face.
    """
    import vtk
    from vtk.util import numpy_support as ns

    reader, dims, spacing, arr = volume
    extent = [d * s for d, s in zip(dims, spacing)]
    if domain == "box":
        padded = np.ascontiguousarray(np.pad(arr, 1, mode="edge"))
        image = vtk.vtkImageData()
        image.SetDimensions(dims[0] + 2, dims[1] + 2, dims[2] + 2)
        image.SetSpacing(*spacing)
        # VTK puts voxel centres at origin + i·s: the padding layer at −½s.
        image.SetOrigin(*(-0.5 * s for s in spacing))
        vtk_type = {np.dtype("u1"): vtk.VTK_UNSIGNED_CHAR, np.dtype("<i2"): vtk.VTK_SHORT,
                    np.dtype("<u2"): vtk.VTK_UNSIGNED_SHORT}[arr.dtype]
        sc = ns.numpy_to_vtk(padded.ravel(), deep=1, array_type=vtk_type)
        image.GetPointData().SetScalars(sc)
        source = vtk.vtkTrivialProducer()
        source.SetOutput(image)
        port = source.GetOutputPort()
    else:
        # VTK puts voxel centres at origin + i·s; Parallax at (i + ½)·s.
        source = vtk.vtkImageChangeInformation()
        source.SetInputConnection(reader.GetOutputPort())
        source.SetOutputOrigin(*(0.5 * s for s in spacing))
        source.Update()
        port = source.GetOutputPort()

    # Transfer function, sampled at every data value: colour linear in RGB;
    # opacity per unit distance α = 1 − exp(−τ·1 mm) (piecewise-linear α is
    # not piecewise-linear τ, hence the dense sampling; VTK's tables are
    # indexed by integer data value anyway).
    xs = np.arange(float(arr.min()), float(arr.max()) + 1.0)
    tau, col = tf_at(tf, xs)
    ctf = vtk.vtkColorTransferFunction()
    ctf.SetColorSpaceToRGB()
    otf = vtk.vtkPiecewiseFunction()
    for x, t, c in zip(xs, tau, col):
        ctf.AddRGBPoint(x, *c)
        otf.AddPoint(x, 1.0 - math.exp(-t * 1.0))
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(ctf)
    prop.SetScalarOpacity(otf)
    prop.SetScalarOpacityUnitDistance(1.0)
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOff()

    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputConnection(port)
    mapper.SetBlendModeToComposite()
    mapper.SetNumberOfThreads(threads)
    mapper.AutoAdjustSampleDistancesOff()
    mapper.LockSampleDistanceToInputSpacingOff()
    mapper.SetImageSampleDistance(1.0)
    mapper.SetFinalColorWindow(1.0)
    mapper.SetFinalColorLevel(0.5)
    if domain == "box":
        mapper.CroppingOn()
        mapper.SetCroppingRegionPlanes(0.0, extent[0], 0.0, extent[1], 0.0, extent[2])
        mapper.SetCroppingRegionFlagsToSubVolume()

    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)

    ren = vtk.vtkRenderer()
    ren.AddVolume(volume)
    ren.SetBackground(0.0, 0.0, 0.0)
    ren.SetBackgroundAlpha(0.0)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetAlphaBitPlanes(1)
    win.SetMultiSamples(0)
    win.AddRenderer(ren)
    win.SetSize(W, H)

    # The camera, in volume space (mm): the inverse placement of the eye, of
    # the screen centre and of display +y; vertical view angle through the
    # screen's top and bottom edges. The screen plane is perpendicular to the
    # eye→centre line, so VTK's symmetric frustum is exactly the window.
    cam = ren.GetActiveCamera()
    cam.ParallelProjectionOff()
    cam.SetPosition(*placement.to_volume(EYE))
    cam.SetFocalPoint(*placement.to_volume([0.0, 0.0, 0.0]))
    cam.SetViewUp(*placement.dir_to_volume([0.0, 1.0, 0.0]))
    cam.SetViewAngle(math.degrees(2.0 * math.atan(SCREEN[1] / 2 / EYE[2])))
    cam.UseHorizontalViewAngleOff()
    ren.ResetCameraClippingRange()

    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.SetInputBufferTypeToRGBA()
    grab.ReadFrontBufferOff()
    grab.ShouldRerenderOff()

    info = {
        "vtk_version": vtk.vtkVersion.GetVTKVersion(),
        "threads": mapper.GetNumberOfThreads(),
        "global_default_threads": vtk.vtkMultiThreader.GetGlobalDefaultNumberOfThreads(),
        "window_class": win.GetClassName(),
        "volume_bounds": volume.GetBounds(),
        "cropping": mapper.GetCropping() and mapper.GetCroppingRegionPlanes(),
        "camera_position": cam.GetPosition(),
        "camera_focal_point": cam.GetFocalPoint(),
        "camera_view_up": cam.GetViewUp(),
        "camera_view_angle": cam.GetViewAngle(),
        "clipping_range": cam.GetClippingRange(),
    }
    return dict(vtk=vtk, ns=ns, mapper=mapper, win=win, ren=ren, grab=grab, info=info,
                keep=(source, volume, prop))


def vtk_read_framebuffer(v):
    """The window's RGBA (8 bit per channel), top row first, as float."""
    v["grab"].Modified()
    v["grab"].Update()
    out = v["grab"].GetOutput()
    w, h, _ = out.GetDimensions()
    a = v["ns"].vtk_to_numpy(out.GetPointData().GetScalars()).reshape(h, w, 4)
    return a[::-1].astype(np.float32) / 255.0


def vtk_read_raycast_image(v):
    """The mapper's own ray-cast image (15-bit fixed point, before it is drawn
    into the 8-bit framebuffer), top row first, as float."""
    im = v["mapper"].GetRayCastImage()
    vw, vh = im.GetImageViewportSize()
    mw, mh = im.GetImageMemorySize()
    uw, uh = im.GetImageInUseSize()
    ox, oy = im.GetImageOrigin()
    assert (vw, vh) == (W, H), (vw, vh)
    m = re.match(r"_([0-9a-fA-F]+)_p_", im.GetImage())
    assert m, im.GetImage()
    buf = (ctypes.c_uint16 * (mw * mh * 4)).from_address(int(m.group(1), 16))
    data = np.frombuffer(buf, dtype=np.uint16).reshape(mh, mw, 4)[:uh, :uw].astype(np.float32)
    full = np.zeros((H, W, 4), np.float32)
    full[oy:oy + uh, ox:ox + uw] = data / 32767.0
    return full[::-1].copy()


def vtk_run(v, sample_distance, repeats):
    """Median wall time of renWin.Render() over `repeats` undisturbed renders
    after one warm-up (tables, min-max volume, GL context)."""
    v["mapper"].SetSampleDistance(sample_distance)
    v["win"].Render()
    times, cores, others = [], [], []
    disturbed = 0
    wait_idle()
    while len(times) < repeats:
        with Meter() as m:
            v["win"].Render()
        if m.other_cores > 0.1:
            disturbed += 1
            if disturbed <= 20:
                log(f"    (render disturbed: other processes {m.other_cores:.2f} cores; again)")
                wait_idle()
                continue
            if disturbed == 21:
                log("    WARNING: could not get undisturbed renders; keeping disturbed ones")
        times.append(m.wall * 1e3)
        cores.append(m.cores)
        others.append(m.other_cores)
    return (times, statistics.median(cores), max(others),
            vtk_read_framebuffer(v), vtk_read_raycast_image(v))
