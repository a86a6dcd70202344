//! The Looking Glass interleaving on the GPU (`shaders/lenticular.wgsl`)
//! against an independent implementation of the published mapping (the
//! conversion of Looking Glass WebXR's `LookingGlassConfig.ts` and its
//! lenticular shader, written here again in f64 from the formulas), on a
//! synthetic quilt whose every texel says which view, place and channel it
//! is, for a portrait and a landscape device, flips included. Neighbouring
//! views differ by one step of a byte, so a sub-pixel on a view boundary
//! that f32 and f64 place on different sides differs by at most 1/255;
//! pixels where a phase lies within 2e-4 of a whole number (0.12 %), where
//! the last view meets the first and f32 cannot tell them apart, are left
//! out of the comparison and counted.

use parallax_backend::gpu::Gpu;
use parallax_backend::lenticular::Interleaver;
use parallax_backend::output::{rgb8, srgb8};
use parallax_common::lenticular::LookingGlass;

/// A Looking Glass Portrait (1536×2048, 48 views as 8×6). Its optical
/// values are a real unit's; the other fields are the device template's.
const PORTRAIT: &str = r#"{ "configVersion": "3.0", "serial": "LKG-P0XXXX",
  "pitch": {"value": 52.59267044067383}, "slope": {"value": -7.083540916442871},
  "center": {"value": 0.8167931437492371}, "fringe": {"value": 0.0},
  "viewCone": {"value": 40.0}, "invView": {"value": 1.0}, "verticalAngle": {"value": 0.0},
  "DPI": {"value": 324.0}, "screenW": {"value": 1536.0}, "screenH": {"value": 2048.0},
  "flipImageX": {"value": 0.0}, "flipImageY": {"value": 0.0}, "flipSubp": {"value": 0.0} }"#;

/// A 16" Looking Glass (3840×2160, 49 views as 7×7): a real gen-3 file.
const LANDSCAPE: &str = r#"{ "configVersion": "3.0", "serial": "LKG-J00133",
  "pitch": {"value": 44.74761962890625}, "slope": {"value": -6.855094909667969},
  "center": {"value": -0.26516956090927126}, "fringe": {"value": 0.0},
  "viewCone": {"value": 50.0}, "invView": {"value": 0.0}, "verticalAngle": {"value": 0.0},
  "DPI": {"value": 283.0}, "screenW": {"value": 3840.0}, "screenH": {"value": 2160.0},
  "flipImageX": {"value": 0.0}, "flipImageY": {"value": 0.0}, "flipSubp": {"value": 0.0},
  "CellPatternMode": {"value": 2.0} }"#;

/// The byte a texel's channel shows: its view, a checkerboard of its place
/// (3-texel squares) and its channel. Neighbouring views differ by one.
fn code(view: u32, x: u32, y: u32, c: usize) -> u8 {
    (view + 80 * ((x / 3 + y / 3) % 2) + 40 * c as u32) as u8
}

/// The linear value whose sRGB byte is `b`.
fn linear(b: u8) -> f32 {
    let c = b as f64 / 255.0;
    let l = if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    };
    l as f32
}

/// Phases this close to a whole number wrap from the last view to the
/// first within an f32 rounding of the phase (|a| up to ~600): there the
/// view is not determined by the mapping at the GPU's precision.
const WRAP: f64 = 2e-4;

/// The published mapping, in f64: the byte each sub-pixel of the panel
/// shows, and whether one of its phases lies within [`WRAP`] of a wrap.
fn reference(j: &serde_json::Value, quilt: [u32; 2], view: [u32; 2]) -> Vec<([u8; 3], bool)> {
    let g = |k: &str| j[k]["value"].as_f64().unwrap();
    let (w, h, dpi, slope) = (g("screenW"), g("screenH"), g("DPI"), g("slope"));
    let flip = |k: &str| g(k) >= 0.5;
    let sign = if flip("flipImageX") { -1.0 } else { 1.0 };
    let pitch = g("pitch") * w / dpi * (1.0f64 / slope).atan().cos();
    let tilt = h / (w * slope) * sign;
    let subp = 1.0 / (w * 3.0) * sign;
    let n = quilt[0] * quilt[1];
    let [vw, vh] = view;
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h as u32 {
        for x in 0..w as u32 {
            let u = (x as f64 + 0.5) / w;
            let v = 1.0 - (y as f64 + 0.5) / h;
            let su = if flip("flipImageX") { 1.0 - u } else { u };
            let sv = if flip("flipImageY") { 1.0 - v } else { v };
            let tx = ((su * vw as f64) as u32).min(vw - 1);
            let ty = (((1.0 - sv) * vh as f64) as u32).min(vh - 1);
            let mut px = [0u8; 3];
            let mut wraps = false;
            for (c, p) in px.iter_mut().enumerate() {
                let k = if flip("flipSubp") && c != 1 { 2 - c } else { c };
                let a = (u + k as f64 * subp + v * tilt) * pitch - g("center");
                let mut f = a - a.floor();
                wraps |= !(WRAP..1.0 - WRAP).contains(&f);
                if g("invView") >= 0.5 {
                    f = 1.0 - f;
                }
                let view = ((f * n as f64) as u32).min(n - 1);
                *p = code(view, tx, ty, c);
            }
            out.push((px, wraps));
        }
    }
    out
}

fn check(gpu: &Gpu, il: &Interleaver, name: &str, text: &str, quilt: [u32; 2], view: [u32; 2]) {
    let lg = LookingGlass::from_visual_json(text, quilt, name).unwrap();
    let [vw, vh] = view;
    let views: Vec<Vec<[f32; 4]>> = (0..lg.views())
        .map(|i| {
            (0..vh)
                .flat_map(|y| (0..vw).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let l = |c| linear(code(i, x, y, c));
                    [l(0), l(1), l(2), 1.0]
                })
                .collect()
        })
        .collect();
    let panel = il.panel(gpu, &lg, &views, view).unwrap();
    let got = rgb8(&panel);
    let want = reference(&serde_json::from_str(text).unwrap(), quilt, view);
    assert_eq!(got.len(), want.len() * 3);
    let (mut worst, mut equal, mut wrapping) = (0u8, 0usize, 0usize);
    let mut seen = vec![false; lg.views() as usize];
    for (g, (w, wraps)) in got.chunks_exact(3).zip(&want) {
        seen[((w[1] - 40) % 80) as usize] = true;
        if *wraps {
            wrapping += 1;
            continue;
        }
        let d = (0..3).map(|c| g[c].abs_diff(w[c])).max().unwrap();
        worst = worst.max(d);
        equal += (d == 0) as usize;
    }
    let share = equal as f64 / want.len() as f64;
    let wrap_share = wrapping as f64 / want.len() as f64;
    eprintln!(
        "{name}: max difference {worst}/255, {:.4} % of the pixels equal, {:.4} % at a phase wrap",
        100.0 * share,
        100.0 * wrap_share
    );
    assert!(worst <= 1, "{name}: differs by {worst}/255");
    assert!(
        wrap_share < 0.002,
        "{name}: {wrap_share} of the pixels at a wrap"
    );
    assert!(share > 0.99, "{name}: only {share} of the pixels equal");
    assert!(
        seen.iter().all(|&s| s),
        "{name}: every view shows somewhere"
    );
}

#[test]
fn the_panel_equals_the_published_mapping_for_two_devices_and_their_flips() {
    // The synthetic texels round-trip through the PNG conversion.
    for b in 0..=255u8 {
        assert_eq!(srgb8(linear(b)), b);
    }
    let gpu = Gpu::new().unwrap();
    let il = Interleaver::new(&gpu).unwrap();
    check(&gpu, &il, "portrait", PORTRAIT, [8, 6], [96, 128]);
    check(&gpu, &il, "landscape", LANDSCAPE, [7, 7], [160, 90]);
    // Every flip at once, on both.
    let flipped = |t: &str| {
        t.replace(
            r#""flipImageX": {"value": 0.0}, "flipImageY": {"value": 0.0}, "flipSubp": {"value": 0.0}"#,
            r#""flipImageX": {"value": 1.0}, "flipImageY": {"value": 1.0}, "flipSubp": {"value": 1.0}"#,
        )
    };
    assert_ne!(flipped(PORTRAIT), PORTRAIT);
    check(
        &gpu,
        &il,
        "portrait, flipped",
        &flipped(PORTRAIT),
        [8, 6],
        [96, 128],
    );
    check(
        &gpu,
        &il,
        "landscape, flipped",
        &flipped(LANDSCAPE),
        [7, 7],
        [160, 90],
    );
}
