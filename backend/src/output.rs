//! Images as files (DESIGN.md "Command line"): PNG for people (sRGB, the
//! premultiplied colour over black, as a display shows emission), and `.npy`
//! (float32, H×W×4, linear, premultiplied) for the exact output.

use anyhow::{Context, Result};
use parallax_common::atomic::AtomicFile;
use std::io::Write;
use std::path::Path;

/// Linear [0, 1] → sRGB 8 bit.
pub fn srgb8(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
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
    let data: Vec<u8> = px
        .iter()
        .flat_map(|p| [srgb8(p[0]), srgb8(p[1]), srgb8(p[2])])
        .collect();
    w.write_image_data(&data)?;
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
