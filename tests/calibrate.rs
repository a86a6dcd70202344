//! Projector calibration from a VESA MPCDI file written by an independent
//! writer (Python's zipfile and struct, following the standard: a 2d
//! profile, one buffer, one region, a PFM warp grid with rows bottom to
//! top and content points with the origin at the bottom left, an 8-bit
//! alpha map): `parallax calibrate mpcdi` imports it into the projector
//! file, the imported warp reproduces the file's, and the rendered image
//! of that projector is its uncalibrated image through that warp and blend.

mod support;

use parallax_backend::calibrate::Calibrated;
use parallax_common::config::Display;
use std::path::Path;
use std::process::{Command, Output};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_parallax")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn run(args: &[&str]) -> Output {
    let o = Command::new(bin()).args(args).output().unwrap();
    assert!(
        o.status.success(),
        "parallax {args:?}: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The warp the file describes: output point (s, t) (t down) shows content
/// point (x, y) with the origin at the bottom left.
fn affine(s: f64, t_up: f64) -> [f64; 2] {
    [0.1 + 0.8 * s + 0.05 * t_up, 0.05 + 0.9 * t_up]
}

const WRITER: &str = r#"
import struct, sys, zipfile, zlib
out, gw, gh = sys.argv[1], 5, 4
# The grid fills the output: point (i, j) at ((i + 0.5) / gw, (j + 0.5) / gh)
# from the bottom left; rows stored bottom to top, little endian (scale -1).
pfm = b"PF\n%d %d\n-1.0\n" % (gw, gh)
for j in range(gh):
    for i in range(gw):
        s, t = (i + 0.5) / gw, (j + 0.5) / gh
        pfm += struct.pack("<3f", 0.1 + 0.8 * s + 0.05 * t, 0.05 + 0.9 * t, 0.0)
# An alpha map: 1 on the left, falling to 0.5 on the right, 8-bit grey.
w, h = 16, 8
raw = b"".join(b"\0" + bytes(255 - (x * 127) // (w - 1) for x in range(w)) for y in range(h))
def chunk(k, d):
    return struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d) & 0xffffffff)
png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)) \
    + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
xml = """<?xml version="1.0" encoding="utf-8"?>
<MPCDI profile="2d" geometry="1" color="1" date="2026-12-05 12:00:00" version="2.0">
  <display><buffer id="wall" xResolution="64" yResolution="36">
    <region id="p01" x="0.0" y="0.0" xSize="1.0" ySize="1.0" xResolution="64" yResolution="36">
      <color><decode type="gamma" gamma="2.2"/><encode type="gamma" gamma="2.2"/></color>
    </region>
  </buffer></display>
  <files><fileset region="p01">
    <geometryWarpFile><path>p01.pfm</path><interpolation>linear</interpolation></geometryWarpFile>
    <alphaMap><bitDepth>8</bitDepth><componentDepth>1</componentDepth>
      <gammaEmbedded>2.2</gammaEmbedded><path>p01_alpha.png</path></alphaMap>
  </fileset></files>
</MPCDI>
"""
with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
    z.writestr("mpcdi.xml", xml)
    z.writestr("p01.pfm", pfm)
    z.writestr("p01_alpha.png", png)
"#;

#[test]
fn an_mpcdi_region_imports_and_its_warp_and_blend_shape_the_projectors_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    support::volume(d, "shells", 40);
    run(&[
        "display-gen",
        "--projectors",
        "2",
        "--resolution",
        "64x36",
        "--pixel-size",
        "0.025",
        "-o",
        s(&d.join("wall")),
    ]);
    std::fs::write(
        d.join("scene.toml"),
        "volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\ndisplay = \"wall/display.toml\"\n[placement]\ncenter = [0, 0, 0.1]\nsize = 0.5\nrotation_deg = [15, 30, 0]\n[render]\neta = 1.0\n",
    )
    .unwrap();
    let render = |out: &str| {
        run(&[
            "render",
            "--scene",
            s(&d.join("scene.toml")),
            "--frames",
            "4",
            "--sync",
            "--float",
            "--out",
            s(&d.join(out)),
        ]);
        let npy = |id: &str| {
            parallax_backend::output::read_npy(&d.join(out).join(format!("frame_00003/{id}.npy")))
                .unwrap()
                .2
        };
        (npy("p00"), npy("p01"))
    };
    let (plain0, plain1) = render("plain");

    let mpcdi = d.join("wall.mpcdi");
    let w = Command::new("python3")
        .args(["-c", WRITER, s(&mpcdi)])
        .output()
        .unwrap();
    assert!(w.status.success(), "{}", String::from_utf8_lossy(&w.stderr));
    let o = run(&[
        "calibrate",
        "mpcdi",
        s(&mpcdi),
        "--projectors",
        s(&d.join("wall/projectors")),
    ]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("calibrated 1 projector(s)"));

    // The imported warp is the file's: inside the grid's outer points it
    // is the affine map the file samples (bilinear between grid points
    // reproduces it).
    let display = Display::load(&d.join("wall/display.toml")).unwrap();
    let p1 = &display.projectors[1];
    assert_eq!(p1.id, "p01");
    assert!(display.projectors[0].calibration.is_none());
    let cal = Calibrated::load(p1.calibration.as_ref().unwrap(), "p01").unwrap();
    let res = [64u32, 36];
    let mut checked = 0;
    for y in 5..31u32 {
        for x in 7..57u32 {
            let (sx, ty) = ((x as f64 + 0.5) / 64.0, (y as f64 + 0.5) / 36.0);
            let [u, v] = affine(sx, 1.0 - ty);
            let got = cal.source(x, y, res);
            let want = [u * 64.0, (1.0 - v) * 36.0];
            assert!(
                (got[0] - want[0]).abs() < 1e-3 && (got[1] - want[1]).abs() < 1e-3,
                "output ({x}, {y}): shows {got:?}, the file says {want:?}"
            );
            checked += 1;
        }
    }
    assert!(checked > 1000);

    // The calibrated render: p01 is its plain image warped and blended,
    // p00 is untouched.
    let (cal0, cal1) = render("calibrated");
    assert_eq!(cal0, plain0);
    let want = cal.apply(&plain1, res);
    let worst = cal1
        .iter()
        .zip(&want)
        .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "calibrated p01 differs by {worst}");
    assert_ne!(cal1, plain1);
    // The blend map dims the right edge to 0.5^2.2 of the left's weight.
    let right = cal.apply(&vec![[1.0f32; 4]; 64 * 36], res)[18 * 64 + 63][0];
    assert!((right - 0.5f32.powf(2.2)).abs() < 0.02, "{right}");
}
