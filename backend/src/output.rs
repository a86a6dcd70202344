//! Images as files (docs/design.md "Command line"): PNG for people (sRGB, the
//! premultiplied colour over black, as a display shows emission), and `.npy`
//! (float32, H×W×4, linear, premultiplied) for the exact output.

use anyhow::{Context, Result};
use parallax_common::atomic::AtomicFile;
use std::io::Write;
use std::path::Path;

/// A colour value in [0, 1] (NaN and ±∞ give 0).
fn unit(v: f32) -> f32 {
    if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Linear [0, 1] → sRGB 8 bit: the formula, rounded (NaN and ±∞ give 0).
/// [`srgb8`] gives the same value from tables, for every input.
fn srgb8_formula(v: f32) -> u8 {
    let v = unit(v);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Buckets of [0, 1] in the first guess of [`srgb8`]: fine enough that a
/// bucket spans less than one code (the steepest part, 12.92 · 255 codes
/// per unit, crosses 0.8 of a code per bucket).
const SRGB_BUCKETS: usize = 4096;

struct SrgbTables {
    /// `threshold[k]`: the least f32 in [0, 1] that the formula takes to
    /// code k or above (k ≥ 1; `threshold[0]` = 0).
    threshold: [f32; 256],
    /// The code of every value in bucket i is at least `guess[i]`.
    guess: Vec<u8>,
}

fn srgb_tables() -> &'static SrgbTables {
    static TABLES: std::sync::OnceLock<SrgbTables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        // Non-negative floats are ordered as their bits, and the formula
        // does not decrease: bisect the bits for each code's first value.
        let mut threshold = [0.0f32; 256];
        for (k, t) in threshold.iter_mut().enumerate().skip(1) {
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if (srgb8_formula(f32::from_bits(mid)) as usize) < k {
                    lo = mid + 1;
                } else {
                    hi = mid;
                }
            }
            *t = f32::from_bits(lo);
        }
        // A bucket's guess is the code one bucket lower: the index of a
        // value rounds up at most to its own bucket.
        let guess = (0..=SRGB_BUCKETS)
            .map(|i| {
                let below = i.saturating_sub(1) as f32 / SRGB_BUCKETS as f32;
                threshold[1..].iter().filter(|&&t| t <= below).count() as u8
            })
            .collect();
        SrgbTables { threshold, guess }
    })
}

/// The least linear value of each 8-bit sRGB code (code 0: 0): what a
/// shader needs to give [`srgb8`]'s codes (`shaders/present.wgsl`).
pub fn srgb_thresholds() -> [f32; 256] {
    srgb_tables().threshold
}

/// Linear [0, 1] → sRGB 8 bit, the same code as the formula for every f32
/// (NaN and ±∞ give 0), without a power per value.
pub fn srgb8(v: f32) -> u8 {
    let v = unit(v);
    let t = srgb_tables();
    let mut code = t.guess[(v * SRGB_BUCKETS as f32) as usize] as usize;
    while code < 255 && v >= t.threshold[code + 1] {
        code += 1;
    }
    code as u8
}

/// The 8-bit sRGB colour of each pixel (over black), 3 bytes a pixel, in
/// parallel over runs of pixels.
pub fn rgb8(px: &[[f32; 4]]) -> Vec<u8> {
    use rayon::prelude::*;
    const CHUNK: usize = 4096;
    let mut out = vec![0u8; px.len() * 3];
    out.par_chunks_mut(3 * CHUNK)
        .zip(px.par_chunks(CHUNK))
        .for_each(|(o, p)| {
            for (o, p) in o.chunks_exact_mut(3).zip(p) {
                o.copy_from_slice(&[srgb8(p[0]), srgb8(p[1]), srgb8(p[2])]);
            }
        });
    out
}

fn check_len(path: &Path, width: u32, height: u32, px: &[[f32; 4]]) -> Result<()> {
    anyhow::ensure!(
        px.len() as u64 == width as u64 * height as u64,
        "{}: {} pixels for a {width}×{height} image",
        path.display(),
        px.len()
    );
    Ok(())
}

/// Writes a premultiplied RGBA image as an sRGB PNG (colour over black).
pub fn write_png(path: &Path, width: u32, height: u32, px: &[[f32; 4]]) -> Result<()> {
    check_len(path, width, height, px)?;
    let mut file = AtomicFile::create(path)?;
    let mut enc = png::Encoder::new(&mut file, width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut w = enc.write_header()?;
    w.write_image_data(&rgb8(px))?;
    w.finish()?;
    file.commit()
}

/// Writes H×W×4 float32 values as a NumPy `.npy` file (format 1.0).
pub fn write_npy(path: &Path, width: u32, height: u32, px: &[[f32; 4]]) -> Result<()> {
    check_len(path, width, height, px)?;
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({height}, {width}, 4), }}");
    // magic (6) + version (2) + length (2) + header + '\n', padded to 64
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat(total.next_multiple_of(64) - total));
    header.push('\n');
    let mut f = AtomicFile::create(path)?;
    f.write_all(b"\x93NUMPY\x01\x00")?;
    f.write_all(&(header.len() as u16).to_le_bytes())?;
    f.write_all(header.as_bytes())?;
    f.write_all(bytemuck::cast_slice(px))?;
    f.commit()
}

/// Reads back a file written by [`write_npy`]: (width, height, pixels).
pub fn read_npy(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    let b = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    anyhow::ensure!(
        b.len() > 10 && &b[..8] == b"\x93NUMPY\x01\x00",
        "{}: not a .npy file",
        path.display()
    );
    let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = std::str::from_utf8(&b[10..10 + hl])?;
    let shape = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .with_context(|| format!("{}: no shape", path.display()))?;
    let dims: Vec<u32> = shape
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    anyhow::ensure!(
        dims.len() == 3 && dims[2] == 4,
        "{}: shape {shape}",
        path.display()
    );
    let data = &b[10 + hl..];
    anyhow::ensure!(
        data.len() == (dims[0] * dims[1] * 16) as usize,
        "{}: truncated",
        path.display()
    );
    let px = data
        .chunks_exact(16)
        .map(|c| {
            std::array::from_fn(|i| f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().unwrap()))
        })
        .collect();
    Ok((dims[1], dims[0], px))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tables_give_the_formulas_code_for_every_value_tried() {
        let t = srgb_tables();
        let mut tried = 0u64;
        let mut check = |v: f32| {
            assert_eq!(srgb8(v), srgb8_formula(v), "{v:e} ({:#x})", v.to_bits());
            tried += 1;
        };
        // Around each code's first value, 2000 floats either side: where a
        // table could be off by one.
        for &th in &t.threshold[1..] {
            let b = th.to_bits();
            for d in 0..2000u32 {
                check(f32::from_bits(b + d));
                check(f32::from_bits(b.saturating_sub(d)));
            }
        }
        // Evenly over [0, 1], and what lies outside it.
        for i in 0..=1_000_000u32 {
            check(i as f32 / 1e6);
        }
        for v in [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            -1e-30,
            -3.0,
            1.0,
            1.0 + 1e-7,
            7.5,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
        ] {
            check(v);
        }
        assert!(tried > 2_000_000);
        // Each code has its first value, and the codes do not skip.
        for k in 1..256 {
            let th = t.threshold[k];
            assert_eq!(srgb8_formula(th) as usize, k);
            assert_eq!(
                srgb8_formula(f32::from_bits(th.to_bits() - 1)) as usize,
                k - 1
            );
        }
    }

    #[test]
    fn rgb8_is_the_colour_of_each_pixel_in_order() {
        let px: Vec<[f32; 4]> = (0..10_000)
            .map(|i| {
                let v = i as f32 / 10_000.0;
                [v, 1.0 - v, (v * 7.0).fract(), 0.5]
            })
            .collect();
        let bytes = rgb8(&px);
        assert_eq!(bytes.len(), 30_000);
        for (p, b) in px.iter().zip(bytes.chunks_exact(3)) {
            assert_eq!(
                b,
                [
                    srgb8_formula(p[0]),
                    srgb8_formula(p[1]),
                    srgb8_formula(p[2])
                ]
            );
        }
    }
}
