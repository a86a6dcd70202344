//! Projector calibration: a warp and a blend map per projector, applied to
//! its image before it is written or presented, so that a wall whose
//! projectors are not ideally aligned still shows one picture.
//!
//! A projector file's `[calibration]`:
//!
//! - `homography = [[h11, h12, h13], [h21, h22, h23], [h31, h32, h33]]`:
//!   the output pixel whose centre is (x, y) (pixels, from the top left)
//!   shows the rendered image at H·(x, y, 1), dehomogenised (pixels);
//! - or `mesh = "file.pfm"`: a grid over the projector's output, in the
//!   layout of a VESA MPCDI 2D geometry warp (a PFM of (x, y, error) per
//!   grid point, rows bottom to top, the grid filling the output raster;
//!   each (x, y) the content point shown there, normalised, origin at the
//!   bottom left), interpolated bilinearly;
//! - `blend = "file.png"`: an intensity (alpha) map over the output, grey
//!   or RGB, `blend_gamma` its embedded gamma (MPCDI `gammaEmbedded`, 1 by
//!   default): each output pixel is scaled by pow(α, gamma) (MPCDI §2.4
//!   with β = 0).
//!
//! Sampling is bilinear over the rendered image; points outside it are
//! black.

use anyhow::{bail, ensure, Context, Result};
use parallax_common::config::Calibration;
use std::path::Path;

/// A warp as the output pixel → content point map.
#[derive(Clone, Debug, PartialEq)]
pub enum Warp {
    Homography([[f64; 3]; 3]),
    /// Grid columns, rows, and per point (x, y) normalised with the origin
    /// at the bottom left, rows from the top.
    Mesh {
        size: [usize; 2],
        points: Vec<[f32; 2]>,
    },
}

/// One projector's calibration, ready to apply.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibrated {
    pub warp: Option<Warp>,
    /// The blend map (already raised to its gamma): width, height, values.
    pub blend: Option<([usize; 2], Vec<f32>)>,
}

impl Calibrated {
    /// Reads a projector's calibration (its files' paths made absolute when
    /// the display was loaded). Errors name the file and the field.
    pub fn load(c: &Calibration, what: &str) -> Result<Self> {
        let warp = match (&c.homography, &c.mesh) {
            (Some(_), Some(_)) => {
                bail!("{what}: calibration: give a homography or a mesh, not both")
            }
            (Some(h), None) => {
                ensure!(
                    h.iter().flatten().all(|v| v.is_finite()),
                    "{what}: calibration.homography: every entry must be finite"
                );
                Some(Warp::Homography(*h))
            }
            (None, Some(m)) => {
                let (size, points) =
                    read_pfm(Path::new(m)).with_context(|| format!("{what}: calibration.mesh"))?;
                Some(Warp::Mesh { size, points })
            }
            (None, None) => None,
        };
        let blend = match &c.blend {
            None => None,
            Some(b) => {
                let g = c.blend_gamma.unwrap_or(1.0);
                ensure!(
                    g.is_finite() && g > 0.0 && g < 10.0,
                    "{what}: calibration.blend_gamma: expected a gamma in (0, 10) (got {g})"
                );
                let (size, v) = read_grey_png(Path::new(b))
                    .with_context(|| format!("{what}: calibration.blend"))?;
                Some((size, v.into_iter().map(|a| a.powf(g as f32)).collect()))
            }
        };
        Ok(Calibrated { warp, blend })
    }

    /// The content point (pixels of a `res` image, from its top left) that
    /// output pixel (x, y) of a `res` output shows.
    pub fn source(&self, x: u32, y: u32, res: [u32; 2]) -> [f64; 2] {
        let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
        match &self.warp {
            None => [px, py],
            Some(Warp::Homography(h)) => {
                let w = h[2][0] * px + h[2][1] * py + h[2][2];
                [
                    (h[0][0] * px + h[0][1] * py + h[0][2]) / w,
                    (h[1][0] * px + h[1][1] * py + h[1][2]) / w,
                ]
            }
            Some(Warp::Mesh { size, points }) => {
                let s = px / res[0] as f64;
                let t = py / res[1] as f64;
                let [u, v] = bilinear2(points, *size, s, t);
                [u * res[0] as f64, (1.0 - v) * res[1] as f64]
            }
        }
    }

    /// The calibrated image of a `res` projector: each output pixel shows
    /// its warped content point, scaled by the blend map.
    pub fn apply(&self, img: &[[f32; 4]], res: [u32; 2]) -> Vec<[f32; 4]> {
        let [w, h] = res;
        let mut out = vec![[0.0f32; 4]; img.len()];
        for y in 0..h {
            for x in 0..w {
                let [cx, cy] = self.source(x, y, res);
                let mut p = sample(img, res, cx - 0.5, cy - 0.5);
                if let Some((size, a)) = &self.blend {
                    let s = (x as f64 + 0.5) / w as f64;
                    let t = (y as f64 + 0.5) / h as f64;
                    let alpha = bilinear1(a, *size, s, t) as f32;
                    p = p.map(|c| c * alpha);
                }
                out[(y * w + x) as usize] = p;
            }
        }
        out
    }
}

/// Bilinear sample of an image at texel coordinates (x, y) (texel centres
/// at whole numbers); black outside it.
fn sample(img: &[[f32; 4]], res: [u32; 2], x: f64, y: f64) -> [f32; 4] {
    let [w, h] = res.map(|v| v as i64);
    if !(x > -1.0 && y > -1.0 && x < w as f64 && y < h as f64) {
        return [0.0; 4];
    }
    let (x0, y0) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let at = |i: i64, j: i64| -> [f32; 4] {
        if i < 0 || j < 0 || i >= w || j >= h {
            [0.0; 4]
        } else {
            img[(j * w + i) as usize]
        }
    };
    let (a, b, c, d) = (
        at(x0, y0),
        at(x0 + 1, y0),
        at(x0, y0 + 1),
        at(x0 + 1, y0 + 1),
    );
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bottom = c[k] + (d[k] - c[k]) * fx;
        top + (bottom - top) * fy
    })
}

/// A grid of `size` cells filling [0, 1]² (cell centres at (i + ½)/n, rows
/// from the top), read bilinearly at (s, t), clamped at the edges.
fn grid_at(size: [usize; 2], s: f64, t: f64) -> ([usize; 4], [f64; 2]) {
    let [gw, gh] = size;
    let gx = (s * gw as f64 - 0.5).clamp(0.0, (gw - 1) as f64);
    let gy = (t * gh as f64 - 0.5).clamp(0.0, (gh - 1) as f64);
    let (x0, y0) = (gx.floor() as usize, gy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(gw - 1), (y0 + 1).min(gh - 1));
    (
        [y0 * gw + x0, y0 * gw + x1, y1 * gw + x0, y1 * gw + x1],
        [gx - x0 as f64, gy - y0 as f64],
    )
}

fn bilinear2(points: &[[f32; 2]], size: [usize; 2], s: f64, t: f64) -> [f64; 2] {
    let ([a, b, c, d], [fx, fy]) = grid_at(size, s, t);
    std::array::from_fn(|k| {
        let p = |i: usize| points[i][k] as f64;
        let top = p(a) + (p(b) - p(a)) * fx;
        let bottom = p(c) + (p(d) - p(c)) * fx;
        top + (bottom - top) * fy
    })
}

fn bilinear1(v: &[f32], size: [usize; 2], s: f64, t: f64) -> f64 {
    let ([a, b, c, d], [fx, fy]) = grid_at(size, s, t);
    let top = v[a] as f64 + (v[b] as f64 - v[a] as f64) * fx;
    let bottom = v[c] as f64 + (v[d] as f64 - v[c] as f64) * fx;
    top + (bottom - top) * fy
}

/// A PFM (`PF`, three floats a point) as a grid of (x, y), rows from the
/// top: the file's rows run bottom to top (netpbm's PFM, the layout MPCDI
/// tools read); the scale's sign gives the byte order.
pub fn read_pfm(path: &Path) -> Result<([usize; 2], Vec<[f32; 2]>)> {
    let f = path.display().to_string();
    let d = std::fs::read(path).with_context(|| format!("{f}: cannot read"))?;
    parse_pfm(&d, &f)
}

/// [`read_pfm`] of bytes; `f` names them in errors.
pub fn parse_pfm(d: &[u8], f: &str) -> Result<([usize; 2], Vec<[f32; 2]>)> {
    // The magic, width, height and scale, each ended by one whitespace
    // byte (leading whitespace skipped); the raster follows the scale's.
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 {
        while i < d.len() && d[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while i < d.len() && i < 256 && !d[i].is_ascii_whitespace() {
            i += 1;
        }
        ensure!(
            i < d.len() && i < 256 && i > start,
            "{f}: not a PFM file (its header is cut short)"
        );
        fields.push(String::from_utf8_lossy(&d[start..i]).into_owned());
        i += 1;
    }
    ensure!(
        fields[0] == "PF",
        "{f}: expected a 3-channel PFM ('PF'), found '{}'",
        fields[0]
    );
    let num = |k: usize, what: &str| -> Result<usize> {
        fields[k]
            .parse::<usize>()
            .ok()
            .filter(|&v| (2..=8192).contains(&v))
            .with_context(|| {
                format!(
                    "{f}: {what}: expected 2 to 8192 grid points, got '{}'",
                    fields[k]
                )
            })
    };
    let (w, h) = (num(1, "width")?, num(2, "height")?);
    let scale: f64 = fields[3]
        .parse()
        .ok()
        .filter(|s: &f64| s.is_finite() && *s != 0.0)
        .with_context(|| {
            format!(
                "{f}: scale: expected a non-zero number, got '{}'",
                fields[3]
            )
        })?;
    let data = &d[i..];
    let need = w * h * 12;
    ensure!(
        data.len() >= need,
        "{f}: {w}×{h} points need {need} bytes of data, the file has {}",
        data.len()
    );
    let le = scale < 0.0;
    let mut points = vec![[0f32; 2]; w * h];
    for row in 0..h {
        for x in 0..w {
            let o = (row * w + x) * 12;
            let v = |k: usize| {
                let b: [u8; 4] = data[o + 4 * k..o + 4 * k + 4].try_into().unwrap();
                if le {
                    f32::from_le_bytes(b)
                } else {
                    f32::from_be_bytes(b)
                }
            };
            let (px, py) = (v(0), v(1));
            ensure!(
                px.is_finite() && py.is_finite(),
                "{f}: point ({x}, {row}) is not a number (an unknown location)"
            );
            points[(h - 1 - row) * w + x] = [px, py];
        }
    }
    Ok(([w, h], points))
}

/// A PNG's first channel as values in [0, 1], rows from the top.
fn read_grey_png(path: &Path) -> Result<([usize; 2], Vec<f32>)> {
    let f = path.display();
    let file = std::fs::File::open(path).with_context(|| format!("{f}: cannot read"))?;
    let mut dec = png::Decoder::new(std::io::BufReader::new(file));
    dec.set_transformations(png::Transformations::EXPAND);
    let mut r = dec.read_info().with_context(|| format!("{f}: not a PNG"))?;
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r
        .next_frame(&mut buf)
        .with_context(|| format!("{f}: cannot decode"))?;
    let ch = info.color_type.samples();
    let deep = info.bit_depth == png::BitDepth::Sixteen;
    let step = ch * if deep { 2 } else { 1 };
    let v = buf[..info.buffer_size()]
        .chunks_exact(step)
        .map(|c| {
            if deep {
                u16::from_be_bytes([c[0], c[1]]) as f32 / 65535.0
            } else {
                c[0] as f32 / 255.0
            }
        })
        .collect();
    Ok(([info.width as usize, info.height as usize], v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A homography maps a test pattern's dots where its inverse says: the
    /// brightness centroid of each dot in the calibrated image lies within
    /// half a pixel of H⁻¹ of the dot's centre.
    #[test]
    fn a_homography_moves_a_test_patterns_corners_where_it_says() {
        let res = [160u32, 120];
        // Dots of 3×3 texels at the pattern's corners (centres in pixels).
        let dots = [[20.5, 15.5], [140.5, 15.5], [20.5, 105.5], [140.5, 105.5]];
        let mut img = vec![[0.0f32; 4]; 160 * 120];
        for [cx, cy] in dots {
            for dy in -1i32..=1 {
                for dx in -1i32..=1 {
                    let (x, y) = ((cx as i32 + dx) as usize, (cy as i32 + dy) as usize);
                    img[y * 160 + x] = [1.0; 4];
                }
            }
        }
        // A keystone: output → content.
        let h = [[1.05, 0.08, -6.0], [0.02, 0.97, 3.0], [0.0004, 0.0002, 1.0]];
        let c = Calibrated {
            warp: Some(Warp::Homography(h)),
            blend: None,
        };
        let out = c.apply(&img, res);
        let inv = invert(h);
        for [cx, cy] in dots {
            // Where the dot should land: the output point whose centre H
            // maps to the dot's centre.
            let w = inv[2][0] * cx + inv[2][1] * cy + inv[2][2];
            let ex = (inv[0][0] * cx + inv[0][1] * cy + inv[0][2]) / w;
            let ey = (inv[1][0] * cx + inv[1][1] * cy + inv[1][2]) / w;
            let (mut sx, mut sy, mut m) = (0.0, 0.0, 0.0);
            for y in (ey as i64 - 6).max(0)..(ey as i64 + 7).min(120) {
                for x in (ex as i64 - 6).max(0)..(ex as i64 + 7).min(160) {
                    let v = out[(y * 160 + x) as usize][0] as f64;
                    sx += v * (x as f64 + 0.5);
                    sy += v * (y as f64 + 0.5);
                    m += v;
                }
            }
            assert!(m > 4.0, "the dot at {cx},{cy} shows ({m})");
            let (gx, gy) = (sx / m, sy / m);
            assert!(
                (gx - ex).abs() <= 0.5 && (gy - ey).abs() <= 0.5,
                "dot {cx},{cy}: expected at {ex:.2},{ey:.2}, found at {gx:.2},{gy:.2}"
            );
        }
    }

    fn invert(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        let c = |r0: usize, c0: usize, r1: usize, c1: usize| {
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        [
            [
                c(1, 1, 2, 2) / det,
                -c(0, 1, 2, 2) / det,
                c(0, 1, 1, 2) / det,
            ],
            [
                -c(1, 0, 2, 2) / det,
                c(0, 0, 2, 2) / det,
                -c(0, 0, 1, 2) / det,
            ],
            [
                c(1, 0, 2, 1) / det,
                -c(0, 0, 2, 1) / det,
                c(0, 0, 1, 1) / det,
            ],
        ]
    }

    /// A PFM written little endian reads back bottom row last; crafted or
    /// cut files are refused, naming the file and what is wrong.
    #[test]
    fn pfm_grids_read_and_bad_ones_are_named() {
        let mut d = b"PF\n2 2\n-1.0\n".to_vec();
        for v in [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ] {
            for x in v {
                d.extend(x.to_le_bytes());
            }
        }
        let (size, pts) = parse_pfm(&d, "w.pfm").unwrap();
        assert_eq!(size, [2, 2]);
        // The file's first row is the bottom one.
        assert_eq!(pts, vec![[0.0, 1.0], [1.0, 1.0], [0.0, 0.0], [1.0, 0.0]]);
        let err = |d: &[u8]| parse_pfm(d, "w.pfm").unwrap_err().to_string();
        assert!(err(b"PF\n2 2\n").contains("w.pfm: not a PFM file"));
        assert!(err(b"Pf\n2 2\n-1\n").contains("expected a 3-channel PFM"));
        assert!(err(b"PF\n1 2\n-1\n").contains("width: expected 2 to 8192"));
        assert!(err(b"PF\n2 2\n0\n").contains("scale"));
        assert!(err(&d[..40]).contains("need 48 bytes"));
        let mut nan = d.clone();
        nan[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(err(&nan).contains("point (0, 0) is not a number"));
    }

    #[test]
    fn no_calibration_changes_nothing() {
        let img: Vec<[f32; 4]> = (0..12).map(|i| [i as f32 / 12.0, 0.5, 0.25, 1.0]).collect();
        let c = Calibrated {
            warp: None,
            blend: None,
        };
        assert_eq!(c.apply(&img, [4, 3]), img);
    }
}
