//! TIFF stacks (the `tiff` crate): a folder of 2-D TIFFs, one slice each, in
//! natural order of their names (`slice2` before `slice10`), or one
//! multi-page TIFF, one page a slice. Greyscale samples of 8, 16, 32 and 64
//! bits, integer or float. One page is decoded at a time, so a stack larger
//! than RAM imports within the import's memory budget.
//!
//! Spacing: `--spacing` when given; otherwise ImageJ's metadata when the
//! file has it (XResolution / YResolution in pixels per unit, `spacing=` in
//! the ImageDescription for z); otherwise 1, 1, 1, which the import says.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

use super::{check_finite, check_info};
use crate::volume::{VolumeInfo, VolumeSource, VoxelType};

type TiffDecoder = Decoder<BufReader<File>>;

enum Pages {
    /// One file per slice.
    Files(Vec<PathBuf>),
    /// One multi-page file: the decoder sits on the next page.
    Multi(Box<TiffDecoder>),
}

/// A TIFF stack read slice by slice.
pub struct TiffSource {
    label: String,
    info: VolumeInfo,
    pages: Pages,
    next: usize,
    note: Option<String>,
    rounding: super::Rounding,
    nan_empty: bool,
}

fn open_decoder(path: &Path) -> Result<TiffDecoder> {
    let label = path.display();
    let f = File::open(path).with_context(|| format!("{label}: cannot open"))?;
    let mut limits = Limits::default();
    // A page of a large scan may exceed the crate's 256 MiB default.
    limits.decoding_buffer_size = 1 << 32;
    let dec =
        super::contain::contained(&label.to_string(), "the TIFF decoder", usize::MAX, || {
            Decoder::new(BufReader::with_capacity(1 << 20, f))
                .with_context(|| format!("{label}: not a TIFF file"))
        })?;
    Ok(dec.with_limits(limits))
}

/// Orders names as people number slices: digit runs compare by value.
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    loop {
        match (x.first(), y.first()) {
            (None, None) => return std::cmp::Ordering::Equal,
            (None, _) => return std::cmp::Ordering::Less,
            (_, None) => return std::cmp::Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let n = x.iter().take_while(|c| c.is_ascii_digit()).count();
                let m = y.iter().take_while(|c| c.is_ascii_digit()).count();
                let (p, q) = (&x[..n], &y[..m]);
                let strip = |s: &[u8]| -> usize { s.iter().take_while(|&&c| c == b'0').count() };
                let (p2, q2) = (&p[strip(p)..], &q[strip(q)..]);
                let ord = p2.len().cmp(&q2.len()).then(p2.cmp(q2)).then(n.cmp(&m));
                if ord != std::cmp::Ordering::Equal {
                    return ord;
                }
                x = &x[n..];
                y = &y[m..];
            }
            (Some(c), Some(d)) => {
                if c != d {
                    return c.cmp(d);
                }
                x = &x[1..];
                y = &y[1..];
            }
        }
    }
}

fn is_tiff_name(p: &Path) -> bool {
    let n = p
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    n.ends_with(".tif") || n.ends_with(".tiff")
}

/// The TIFF files of a folder, in natural order.
pub fn stack_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list the folder", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_tiff_name(p))
        .collect();
    files.sort_by(|a, b| {
        natural_cmp(
            &a.file_name().unwrap_or_default().to_string_lossy(),
            &b.file_name().unwrap_or_default().to_string_lossy(),
        )
    });
    Ok(files)
}

/// What a page is: width, height, sample type.
fn page_shape(dec: &mut TiffDecoder, label: &str) -> Result<(usize, usize, ColorType)> {
    let (w, h) = dec
        .dimensions()
        .with_context(|| format!("{label}: ImageWidth/ImageLength"))?;
    let ct = dec
        .colortype()
        .with_context(|| format!("{label}: PhotometricInterpretation/BitsPerSample"))?;
    match ct {
        ColorType::Gray(8 | 16 | 32 | 64) => {}
        other => bail!(
            "{label}: colour type {other:?}: only greyscale stacks of 8, 16, 32 or 64 bits import \
             (PhotometricInterpretation/BitsPerSample/SamplesPerPixel)"
        ),
    }
    Ok((w as usize, h as usize, ct))
}

/// ImageJ's spacing, when the file carries its metadata.
fn imagej_spacing(dec: &mut TiffDecoder) -> Option<[f64; 3]> {
    let desc = dec.get_tag_ascii_string(Tag::ImageDescription).ok()?;
    if !desc.starts_with("ImageJ=") {
        return None;
    }
    let res = |dec: &mut TiffDecoder, tag| -> Option<f64> {
        let v = match dec.find_tag(tag).ok()?? {
            tiff::decoder::ifd::Value::Rational(n, d) if n > 0 && d > 0 => d as f64 / n as f64,
            tiff::decoder::ifd::Value::Float(f) if f > 0.0 => 1.0 / f as f64,
            tiff::decoder::ifd::Value::Double(f) if f > 0.0 => 1.0 / f,
            _ => return None,
        };
        v.is_finite().then_some(v)
    };
    let sx = res(dec, Tag::XResolution).unwrap_or(1.0);
    let sy = res(dec, Tag::YResolution).unwrap_or(sx);
    let sz = desc
        .lines()
        .find_map(|l| l.strip_prefix("spacing="))
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite() && *v > 0.0)
        .unwrap_or(sx);
    Some([sx, sy, sz])
}

/// Opens a folder of TIFFs or one multi-page TIFF.
pub fn open_tiff(path: &Path, spacing: Option<[f64; 3]>) -> Result<TiffSource> {
    let label = path.display().to_string();
    let (files, mut first, count, first_label) = if path.is_dir() {
        let files = stack_files(path)?;
        ensure!(
            !files.is_empty(),
            "{label}: no .tif or .tiff files in the folder"
        );
        let dec = open_decoder(&files[0])?;
        let n = files.len();
        let l = files[0].display().to_string();
        (Some(files), dec, n, l)
    } else {
        // Count the pages first (reads only the chain of page directories).
        let mut dec = open_decoder(path)?;
        let mut n = 1;
        while dec.more_images() {
            super::contain::contained(&label, "the TIFF decoder", usize::MAX, || {
                dec.next_image()
                    .with_context(|| format!("{label}: page {}: broken page chain", n + 1))
            })?;
            n += 1;
        }
        (None, open_decoder(path)?, n, label.clone())
    };
    let (w, h, _) = page_shape(&mut first, &first_label)?;
    let voxel_type = sample_type(&mut first, &first_label)?;
    let mut note = None;
    let spacing = match spacing {
        Some(s) => s,
        None => match imagej_spacing(&mut first) {
            Some(s) => s,
            None => {
                note = Some(format!(
                    "{label}: no spacing in the TIFF metadata; voxels are taken as 1×1×1 (give --spacing sx,sy,sz)"
                ));
                [1.0; 3]
            }
        },
    };
    let info = VolumeInfo {
        dims: [w, h, count],
        spacing,
        voxel_type,
    };
    check_info(&label, &info, "ImageWidth/ImageLength", "spacing")?;
    let pages = match files {
        Some(f) => Pages::Files(f),
        None => Pages::Multi(Box::new(first)),
    };
    Ok(TiffSource {
        label,
        info,
        pages,
        next: 0,
        note,
        rounding: Default::default(),
        nan_empty: false,
    })
}

/// The sample type of the current page, from SampleFormat and BitsPerSample.
fn sample_type(dec: &mut TiffDecoder, label: &str) -> Result<VoxelType> {
    let bits = dec.get_tag_unsigned::<u16>(Tag::BitsPerSample).unwrap_or(8);
    // SampleFormat: 1 unsigned, 2 signed, 3 float.
    let format = dec
        .find_tag_unsigned::<u16>(Tag::SampleFormat)
        .ok()
        .flatten()
        .unwrap_or(1);
    Ok(match (format, bits) {
        (1, 8) => VoxelType::U8,
        (1, 16) => VoxelType::U16,
        (1, 32) => VoxelType::U32,
        (2, 8) => VoxelType::I8,
        (2, 16) => VoxelType::I16,
        (2, 32) => VoxelType::I32,
        (3, 32) => VoxelType::F32,
        (3, 64) => VoxelType::F64,
        _ => bail!("{label}: SampleFormat {format} with BitsPerSample {bits} is not supported"),
    })
}

impl TiffSource {
    /// Decodes page (slice) `k` into `out`; pages come in order.
    fn read_page(&mut self, k: usize, out: &mut [f32]) -> Result<()> {
        let nz = self.info.dims[2];
        let (page_label, result) = match &mut self.pages {
            Pages::Files(files) => {
                let l = files[k].display().to_string();
                let mut dec = open_decoder(&files[k])?;
                let (w, h, _) = page_shape(&mut dec, &l)?;
                ensure!(
                    [w, h] == [self.info.dims[0], self.info.dims[1]],
                    "{l}: {w}×{h} pixels, but the stack's first slice is {}×{}",
                    self.info.dims[0],
                    self.info.dims[1]
                );
                let t = sample_type(&mut dec, &l)?;
                ensure!(
                    t == self.info.voxel_type,
                    "{l}: {} samples, but the stack's first slice has {}",
                    t.name(),
                    self.info.voxel_type.name()
                );
                let r = super::contain::contained(&l, "the TIFF decoder", usize::MAX, || {
                    dec.read_image()
                        .with_context(|| format!("{l}: reading the image"))
                });
                (l, r)
            }
            Pages::Multi(dec) => {
                let l = format!("{}: page {} of {nz}", self.label, k + 1);
                if k > 0 {
                    super::contain::contained(&l, "the TIFF decoder", usize::MAX, || {
                        dec.next_image()
                            .with_context(|| format!("{l}: broken page chain"))
                    })?;
                }
                let (w, h, _) = page_shape(dec, &l)?;
                ensure!(
                    [w, h] == [self.info.dims[0], self.info.dims[1]],
                    "{l}: {w}×{h} pixels, but the first page is {}×{}",
                    self.info.dims[0],
                    self.info.dims[1]
                );
                let r = super::contain::contained(&l, "the TIFF decoder", usize::MAX, || {
                    dec.read_image()
                        .with_context(|| format!("{l}: reading the image"))
                });
                (l, r)
            }
        };
        let result = result?;
        let n = out.len();
        macro_rules! fill {
            ($v:expr, $exact:expr) => {{
                let v = $v;
                ensure!(
                    v.len() == n,
                    "{page_label}: {} samples, expected {n}",
                    v.len()
                );
                for (o, &s) in out.iter_mut().zip(v.iter()) {
                    *o = s as f32;
                    if $exact {
                        self.rounding.add_value(s as f64, *o);
                    }
                }
            }};
        }
        match result {
            DecodingResult::U8(v) => fill!(v, false),
            DecodingResult::U16(v) => fill!(v, false),
            DecodingResult::I8(v) => fill!(v, false),
            DecodingResult::I16(v) => fill!(v, false),
            DecodingResult::U32(v) => fill!(v, true),
            DecodingResult::I32(v) => fill!(v, true),
            DecodingResult::F32(v) => fill!(v, false),
            DecodingResult::F64(v) => fill!(v, true),
            _ => bail!("{page_label}: unsupported sample type"),
        }
        check_finite(
            &self.label,
            self.info.dims,
            (k * n) as u64,
            out,
            self.nan_empty,
        )
    }
}

impl VolumeSource for TiffSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, out: &mut [f32]) -> Result<()> {
        let label = self.label.clone();
        let info = self.info.clone();
        let mut next = self.next;
        let res = super::slice_by_slice(&label, &info, &mut next, out, |k, chunk| {
            self.read_page(k, chunk)
        });
        self.next = next;
        res
    }

    fn conversion_note(&self) -> Option<String> {
        self.rounding.note_for(&self.label, self.info.voxel_type)
    }

    fn describe(&self) -> Option<String> {
        self.note.clone()
    }

    fn set_nan_empty(&mut self) {
        self.nan_empty = true;
    }
}
