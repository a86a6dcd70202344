"""What bench/vtk_compare.py and the scripts beside it share: the shared
machine's quiet (timing only when nothing else runs), the scene placement
and its inverse, the transfer function as VTK reads it, and image metrics
(those of `parallax bench`: RMSE, max abs, PSNR with peak 1)."""

import math
import os
import struct
import time
import tomllib
import zlib
from pathlib import Path

import numpy as np

def log(*a):
    print(*a, flush=True)


# --------------------------------------------------------------------------
# The machine is shared (2 cores): time only when nothing else runs, and
# measure how much CPU other processes took during each timed section.

def busy_seconds():
    """CPU seconds all cores have spent busy since boot (/proc/stat)."""
    f = [int(x) for x in open("/proc/stat").readline().split()[1:]]
    idle = f[3] + f[4]
    return (sum(f[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def own_cpu(children=False):
    t = os.times()
    return t.children_user + t.children_system if children else t.user + t.system


class Meter:
    """Wall time, own CPU and other processes' CPU over a section."""

    def __init__(self, children=False):
        self.children = children

    def __enter__(self):
        self.b0, self.c0, self.t0 = busy_seconds(), own_cpu(self.children), time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.t0
        self.cpu = own_cpu(self.children) - self.c0
        # (/proc/stat ticks at 1/100 s: allow that much jitter.)
        self.other = max(0.0, busy_seconds() - self.b0 - self.cpu - 0.02)
        self.other_cores = self.other / max(self.wall, 1e-9)
        self.cores = self.cpu / max(self.wall, 1e-9)


# Seconds of quiet a timed section waits for (--quiet).
QUIET_S = 10.0


def wait_idle(limit_cores=0.1, quiet_s=None, timeout_s=3600.0):
    """Waits until other processes have used less than `limit_cores` over
    `quiet_s` seconds in a row (sampled each second; QUIET_S by default)."""
    quiet_s = QUIET_S if quiet_s is None else quiet_s
    t0 = time.time()
    warned = False
    quiet = 0.0
    while quiet < quiet_s:
        with Meter() as m:
            time.sleep(1.0)
        if m.other_cores < limit_cores:
            quiet += m.wall
            continue
        quiet = 0.0
        if not warned:
            log(f"    (machine busy: {m.other_cores:.2f} cores used by other processes; waiting)")
            warned = True
        if time.time() - t0 > timeout_s:
            log("    WARNING: machine still busy after waiting; timing anyway")
            return False
    return True


# --------------------------------------------------------------------------
# Geometry: the scene placement (docs/design.md "Volume space") and its inverse.

def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


class Placement:
    """p (volume, mm) ↦ center + R·(size/max(N·s))·(p − N·s/2); R = Rz·Ry·Rx."""

    def __init__(self, center, size, rotation_deg, extent):
        rx, ry, rz = (math.radians(d) for d in rotation_deg)
        self.R = rot_z(rz) @ rot_y(ry) @ rot_x(rx)
        self.center = np.asarray(center, float)
        self.extent = np.asarray(extent, float)
        self.scale = size / max(extent)

    def to_display(self, p):
        return self.center + self.R @ ((np.asarray(p, float) - self.extent / 2) * self.scale)

    def to_volume(self, x):
        return self.R.T @ (np.asarray(x, float) - self.center) / self.scale + self.extent / 2

    def dir_to_volume(self, d):
        return self.R.T @ np.asarray(d, float)


# --------------------------------------------------------------------------
# The transfer function (docs/design.md "Transfer function").

def load_tf(path):
    pts = tomllib.loads(Path(path).read_text())["point"]
    pts = sorted(pts, key=lambda p: p["value"])
    v = np.array([p["value"] for p in pts], float)
    col = np.array([p["color"] for p in pts], float)
    tau = np.array([p["extinction"] for p in pts], float)
    return v, col, tau


def tf_at(tf, x):
    """τ(x) and c(x): piecewise linear, constant beyond the ends."""
    v, col, tau = tf
    t = np.interp(x, v, tau)
    c = np.stack([np.interp(x, v, col[:, k]) for k in range(3)], axis=-1)
    return t, c


# --------------------------------------------------------------------------
# Image metrics.

def image_error(img, ref):
    d = img.astype(np.float64) - ref.astype(np.float64)
    rmse = float(np.sqrt(np.mean(d * d)))
    return rmse, float(np.max(np.abs(d))), -20.0 * math.log10(max(rmse, 1e-12))


def alpha_centroid(img):
    a = img[..., 3].astype(np.float64)
    ys, xs = np.mgrid[0:a.shape[0], 0:a.shape[1]]
    s = a.sum()
    return float((a * (xs + 0.5)).sum() / s), float((a * (ys + 0.5)).sum() / s)


def best_shift(img, ref, r=2):
    """The whole-pixel shift (dx, dy) of `img` that best matches `ref`."""
    best = None
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            sh = np.roll(np.roll(img, dy, axis=0), dx, axis=1)
            e = float(np.sqrt(np.mean((sh[r:-r, r:-r] - ref[r:-r, r:-r]) ** 2)))
            if best is None or e < best[0]:
                best = (e, dx, dy)
    return best[1], best[2]


def write_png(path, rgb):
    """8-bit RGB PNG without any imaging library."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[j].tobytes() for j in range(h))

    def chunk(t, d):
        c = struct.pack(">I", len(d)) + t + d
        return c + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    Path(path).write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )


def to_srgb8(img):
    c = np.clip(img[..., :3], 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)
