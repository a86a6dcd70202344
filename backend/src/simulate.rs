//! What one eye sees on a light field display, given the projector images of
//! one frame (`parallax simulate`).
//!
//! The model is the display of G10 §3: a holographic screen lit from behind
//! by a horizontal array of projectors. Each projector's beam through a
//! screen point Q keeps its horizontal direction (E→Q) but is diffused
//! horizontally over the screen's angular accuracy Φ (G10 §6: "0.8° angular
//! accuracy") and widely in the vertical ("horizontal parallax only", G10 §4).
//! So an eye at W sees at Q the projectors whose beams through Q pass nearest
//! to W horizontally. G10 gives only the width Φ of that diffusion; its
//! profile here is a tent, w = max(0, 1 − |δ|/Φ), chosen so that
//! neighbouring projectors Φ apart blend linearly into the continuous
//! horizontal parallax G10 §6 reports.
//!
//! With η = 1 (G10 Eq. 1) every projector pixel holds what an observer at the
//! observer's height and distance sees along that beam, so the simulated
//! view from an eye on that line tends to the eye's own perspective view as
//! the projectors get denser: this is what the tests measure.

use crate::output::read_npy;
use anyhow::{bail, Context, Result};
use parallax_common::config::Display;
use rayon::prelude::*;
use std::path::Path;

/// Longest side of the default output image (pixels).
pub const DEFAULT_MAX_SIDE: u32 = 2048;

/// The default output resolution: one pixel per screen pixel s0 (the
/// display's spatial resolution on the screen surface, G10 §4), scaled down
/// to at most `max_side` on the longest side, keeping the aspect.
pub fn default_resolution(display: &Display, max_side: u32) -> [u32; 2] {
    let [sw, sh] = display.screen.size;
    let s0 = display.screen.pixel_size;
    let (mut w, mut h) = ((sw / s0).round().max(1.0), (sh / s0).round().max(1.0));
    let cap = max_side.max(1) as f64;
    if w.max(h) > cap {
        let k = cap / w.max(h);
        w = (w * k).round().max(1.0);
        h = (h * k).round().max(1.0);
    }
    [w as u32, h as u32]
}

/// Parses an eye position written `x,y,z` (metres, display space).
pub fn parse_eye(s: &str) -> Result<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("--eye {s}: expected x,y,z in metres"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("--eye {s}: expected three finite numbers x,y,z in metres");
    }
    Ok([v[0], v[1], v[2]])
}

/// `n` eyes evenly spaced from `from` to `to` (both included), for a strip.
pub fn sweep(from: [f64; 3], to: [f64; 3], n: usize) -> Vec<[f64; 3]> {
    match n {
        0 => Vec::new(),
        1 => vec![from],
        _ => (0..n)
            .map(|k| {
                let t = k as f64 / (n - 1) as f64;
                std::array::from_fn(|c| from[c] + t * (to[c] - from[c]))
            })
            .collect(),
    }
}

/// A simulated eye view: premultiplied RGBA, row 0 at the top, over the
/// whole screen rectangle; `lit[i]` tells whether any projector's beam
/// reaches the eye through that pixel (unlit pixels are black).
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    pub resolution: [u32; 2],
    pub image: Vec<[f32; 4]>,
    pub lit: Vec<bool>,
}

/// What an eye at `eye` sees on the display; `images[p]` is projector p's
/// image (in `display.projectors` order, W×H as its resolution, row 0 at the
/// top). See [`simulate_detailed`].
pub fn simulate(
    display: &Display,
    images: &[Vec<[f32; 4]>],
    eye: [f64; 3],
    resolution: [u32; 2],
) -> Result<Vec<[f32; 4]>> {
    Ok(simulate_detailed(display, images, eye, resolution)?.image)
}

/// One projector as the simulation uses it.
struct Beam<'a> {
    e: [f64; 3],
    region: [f64; 4],
    res: [u32; 2],
    image: &'a [[f32; 4]],
}

/// The simulated view and which of its pixels are lit.
///
/// Output pixel (i, j) is the screen point Q = (x0 + (i+½)/W·w,
/// y0 + h − (j+½)/H·h, 0) of the whole screen (docs/design.md "Which ray a pixel
/// gets"). For each projector E_p whose region holds Q and which is on the
/// other side of the screen from the eye (the screen transmits: a beam
/// E_p→Q continues beyond Q), δ_p is the horizontal angle (x–z plane)
/// between Q→W and E_p→Q, and w_p = max(0, 1 − |δ_p|/Φ). The colour is
/// Σ w_p·I_p(Q) / Σ w_p, I_p sampled bilinearly at Q in projector p's
/// pixel grid; Σ w_p = 0 is black. With Φ = 0 the nearest beam (|δ| < 90°)
/// alone lights Q. An eye on the screen plane sees no beam (all black).
pub fn simulate_detailed(
    display: &Display,
    images: &[Vec<[f32; 4]>],
    eye: [f64; 3],
    resolution: [u32; 2],
) -> Result<Simulation> {
    if eye.iter().any(|x| !x.is_finite()) {
        bail!("eye {eye:?}: must be finite");
    }
    if images.len() != display.projectors.len() {
        bail!(
            "{} projector images for {} projectors",
            images.len(),
            display.projectors.len()
        );
    }
    let views = display.views(1.0);
    let mut beams = Vec::with_capacity(views.len());
    for ((p, v), img) in display.projectors.iter().zip(&views).zip(images) {
        let [w, h] = p.resolution;
        if img.len() != w as usize * h as usize {
            bail!(
                "projector '{}': image has {} pixels, its resolution {w}×{h} needs {}",
                p.id,
                img.len(),
                w as usize * h as usize
            );
        }
        if w == 0 || h == 0 {
            continue;
        }
        beams.push(Beam {
            e: p.position,
            region: v.region,
            res: [w, h],
            image: img,
        });
    }
    let [ow, oh] = resolution;
    let n = ow as usize * oh as usize;
    let mut image = vec![[0f32; 4]; n];
    let mut lit = vec![false; n];
    if n == 0 {
        return Ok(Simulation {
            resolution,
            image,
            lit,
        });
    }
    let [sw, sh] = display.screen.size;
    let (x0, y0) = (-sw / 2.0, -sh / 2.0);
    let phi = display.screen.angular_accuracy_deg.to_radians();
    // The horizontal weights depend only on the column: the screen diffuses
    // vertically, so the vertical angle does not enter (G10 §4).
    let columns: Vec<Vec<(usize, f64)>> = (0..ow)
        .into_par_iter()
        .map(|i| {
            let qx = x0 + (i as f64 + 0.5) / ow as f64 * sw;
            column_weights(&beams, qx, eye, phi)
        })
        .collect();
    image
        .par_chunks_mut(ow as usize)
        .zip(lit.par_chunks_mut(ow as usize))
        .enumerate()
        .for_each(|(j, (row, lrow))| {
            let qy = y0 + sh - (j as f64 + 0.5) / oh as f64 * sh;
            for (i, (px, l)) in row.iter_mut().zip(lrow.iter_mut()).enumerate() {
                let qx = x0 + (i as f64 + 0.5) / ow as f64 * sw;
                let mut acc = [0f64; 4];
                let mut total = 0.0;
                for &(p, w) in &columns[i] {
                    let b = &beams[p];
                    if !inside(b.region, qx, qy) {
                        continue;
                    }
                    let c = sample(b.image, b.res, b.region, qx, qy);
                    for k in 0..4 {
                        acc[k] += w * c[k] as f64;
                    }
                    total += w;
                }
                if total > 0.0 {
                    *px = acc.map(|a| (a / total) as f32);
                    *l = true;
                }
            }
        });
    Ok(Simulation {
        resolution,
        image,
        lit,
    })
}

/// Whether Q = (qx, qy) lies in the region [x0, y0, w, h] (edges included).
fn inside(r: [f64; 4], qx: f64, qy: f64) -> bool {
    let eps = 1e-12 * (r[2].abs() + r[3].abs());
    qx >= r[0] - eps && qx <= r[0] + r[2] + eps && qy >= r[1] - eps && qy <= r[1] + r[3] + eps
}

/// Tent weights of the beams through the screen column x = qx that reach
/// the eye (only the horizontal angle matters; the region is checked per
/// pixel).
fn column_weights(beams: &[Beam], qx: f64, eye: [f64; 3], phi: f64) -> Vec<(usize, f64)> {
    // Q→W in the x–z plane (Q_z = 0).
    let (ax, az) = (eye[0] - qx, eye[2]);
    let mut out = Vec::new();
    let mut nearest: Option<(usize, f64)> = None;
    for (p, b) in beams.iter().enumerate() {
        let e = b.e;
        // The screen transmits: the beam E→Q continues on the far side of
        // the screen from E, so only an eye strictly on that side sees it.
        if az * e[2] >= 0.0 || (az * e[2]).is_nan() {
            continue;
        }
        // Outside the projector's columns (rows are checked per pixel).
        let eps = 1e-12 * (b.region[2].abs() + b.region[3].abs());
        if qx < b.region[0] - eps || qx > b.region[0] + b.region[2] + eps {
            continue;
        }
        // E→Q in the x–z plane; never zero since E_z ≠ 0 here.
        let (bx, bz) = (qx - e[0], -e[2]);
        let cross = ax * bz - az * bx;
        let dot = ax * bx + az * bz;
        let delta = cross.abs().atan2(dot);
        if !delta.is_finite() {
            continue;
        }
        if phi > 0.0 {
            let w = 1.0 - delta / phi;
            if w > 0.0 {
                out.push((p, w));
            }
        } else if delta < std::f64::consts::FRAC_PI_2 && nearest.is_none_or(|(_, d)| delta < d) {
            nearest = Some((p, delta));
        }
    }
    if let Some((p, _)) = nearest {
        out.push((p, 1.0));
    }
    out
}

/// Bilinear sample of a W×H image covering `region` at screen point (qx,
/// qy), pixel (i, j) centred at (x0 + (i+½)/W·w, y0 + h − (j+½)/H·h), clamped
/// at the edges.
pub fn sample(image: &[[f32; 4]], res: [u32; 2], region: [f64; 4], qx: f64, qy: f64) -> [f32; 4] {
    let [w, h] = res;
    let u = (qx - region[0]) / region[2] * w as f64 - 0.5;
    let v = (region[1] + region[3] - qy) / region[3] * h as f64 - 0.5;
    let axis = |t: f64, n: u32| -> (usize, usize, f64) {
        let max = (n - 1) as f64;
        let t = if t.is_finite() {
            t.clamp(0.0, max)
        } else {
            0.0
        };
        let i0 = t.floor();
        let i1 = (i0 + 1.0).min(max);
        (i0 as usize, i1 as usize, t - i0)
    };
    let (i0, i1, fx) = axis(u, w);
    let (j0, j1, fy) = axis(v, h);
    let at = |i: usize, j: usize| image[j * w as usize + i];
    let (a, b, c, d) = (at(i0, j0), at(i1, j0), at(i0, j1), at(i1, j1));
    std::array::from_fn(|k| {
        let top = a[k] as f64 * (1.0 - fx) + b[k] as f64 * fx;
        let bot = c[k] as f64 * (1.0 - fx) + d[k] as f64 * fx;
        (top * (1.0 - fy) + bot * fy) as f32
    })
}

/// Several eyes side by side, left to right in `eyes` order: a strip
/// (`eyes.len()`·W)×H, returned with its width and height.
pub fn strip(
    display: &Display,
    images: &[Vec<[f32; 4]>],
    eyes: &[[f64; 3]],
    resolution: [u32; 2],
) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    let [w, h] = resolution;
    let total_w = w as usize * eyes.len();
    let mut out = vec![[0f32; 4]; total_w * h as usize];
    for (k, &eye) in eyes.iter().enumerate() {
        let img = simulate(display, images, eye, resolution)?;
        for j in 0..h as usize {
            let dst = j * total_w + k * w as usize;
            out[dst..dst + w as usize].copy_from_slice(&img[j * w as usize..(j + 1) * w as usize]);
        }
    }
    Ok((total_w as u32, h, out))
}

/// Reads the projector images of one frame, as `parallax render` writes them:
/// `dir/<projector-id>.npy` (linear, premultiplied: the exact output) when
/// present, else `dir/<projector-id>.png` (sRGB, colour over black, decoded
/// to linear). Every image must have its projector's resolution.
pub fn load_frame(display: &Display, dir: &Path) -> Result<Vec<Vec<[f32; 4]>>> {
    if !dir.is_dir() {
        bail!("{}: not a folder of projector images", dir.display());
    }
    let mut out = Vec::with_capacity(display.projectors.len());
    for p in &display.projectors {
        let npy = dir.join(format!("{}.npy", p.id));
        let png = dir.join(format!("{}.png", p.id));
        let (path, (w, h, px)) = if npy.is_file() {
            (npy.clone(), read_npy(&npy)?)
        } else if png.is_file() {
            (png.clone(), read_png_linear(&png)?)
        } else {
            let hint = if has_frame_folders(dir) {
                " (this looks like a render output folder: pass one of its frame_NNNNN folders)"
            } else {
                ""
            };
            bail!(
                "{}: no image for projector '{}' (neither {} nor {}){hint}",
                dir.display(),
                p.id,
                npy.display(),
                png.display()
            );
        };
        if [w, h] != p.resolution {
            bail!(
                "{}: {w}×{h} pixels, but projector '{}' has resolution {}×{}",
                path.display(),
                p.id,
                p.resolution[0],
                p.resolution[1]
            );
        }
        out.push(px);
    }
    Ok(out)
}

fn has_frame_folders(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|rd| {
        rd.filter_map(|e| e.ok())
            .any(|e| e.file_name().to_string_lossy().starts_with("frame_") && e.path().is_dir())
    })
}

/// sRGB-encoded [0, 1] → linear.
fn srgb_to_linear(s: f32) -> f32 {
    if s <= 0.040_45 {
        s / 12.92
    } else {
        ((s + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB 8-bit RGB pixels (the colour over black, as `write_png` writes and
/// the live coordinator streams) as linear opaque RGBA, decoded exactly as
/// [`read_png_linear`] decodes such a PNG.
pub fn linear_from_srgb8(rgb: &[u8]) -> Vec<[f32; 4]> {
    let lut: Vec<f32> = (0..256).map(|v| srgb_to_linear(v as f32 / 255.0)).collect();
    rgb.chunks_exact(3)
        .map(|c| {
            [
                lut[c[0] as usize],
                lut[c[1] as usize],
                lut[c[2] as usize],
                1.0,
            ]
        })
        .collect()
}

/// Reads a PNG as linear premultiplied RGBA: (width, height, pixels). The
/// sRGB values are decoded to linear. A PNG without alpha (as `write_png`
/// writes: the colour over black) is opaque, alpha 1; a PNG with alpha
/// (straight, per the PNG specification) is premultiplied.
pub fn read_png_linear(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    let file =
        std::fs::File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut dec = png::Decoder::new(std::io::BufReader::new(file));
    dec.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = dec
        .read_info()
        .with_context(|| format!("{}: not a PNG file", path.display()))?;
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .with_context(|| format!("{}: cannot decode", path.display()))?;
    let lut: Vec<f32> = (0..256).map(|v| srgb_to_linear(v as f32 / 255.0)).collect();
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => {
            bail!("{}: indexed colour was not expanded", path.display())
        }
    };
    let (w, h) = (info.width as usize, info.height as usize);
    let mut px = Vec::with_capacity(w * h);
    for j in 0..h {
        let line = &buf[j * info.line_size..j * info.line_size + w * channels];
        for c in line.chunks_exact(channels) {
            let (rgb, a) = match channels {
                1 => ([lut[c[0] as usize]; 3], 1.0),
                2 => ([lut[c[0] as usize]; 3], c[1] as f32 / 255.0),
                3 => (
                    [lut[c[0] as usize], lut[c[1] as usize], lut[c[2] as usize]],
                    1.0,
                ),
                _ => (
                    [lut[c[0] as usize], lut[c[1] as usize], lut[c[2] as usize]],
                    c[3] as f32 / 255.0,
                ),
            };
            px.push([rgb[0] * a, rgb[1] * a, rgb[2] * a, a]);
        }
    }
    Ok((info.width, info.height, px))
}
