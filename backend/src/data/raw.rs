//! Raw sample streams: headerless `.raw` files, and the data part of NRRD and
//! NIfTI files once their headers have been read.
//!
//! A [`RawSource`] decodes packed samples (u8, u16, i16, f32; either byte
//! order) one z-slice at a time from any byte stream, so the readers of every
//! format share one streaming, checking decoder (docs/design.md "Data": "It must
//! stream").

use std::fs::File;
use std::io::{self, BufReader, Read};
use std::path::Path;

use crate::volume::{VolumeInfo, VolumeSource, VoxelType};
use anyhow::{bail, ensure, Context, Result};
use flate2::bufread::MultiGzDecoder;

use super::{check_finite, check_info, decode_samples, shape_text, RawParams};

/// Read buffer of the file streams. Large enough that a slice is a handful of
/// system calls, small enough to be irrelevant next to the brick caches.
pub(crate) const READ_BUFFER: usize = 1 << 20;

/// A volume decoded slice by slice from a stream of packed samples.
pub struct RawSource {
    info: VolumeInfo,
    /// How messages name the file ("vol.raw", or "vol.raw (data file of vol.nhdr)").
    label: String,
    reader: Box<dyn Read + Send>,
    /// Sample type in the stream; `info.voxel_type` differs when scaled.
    stored: VoxelType,
    big_endian: bool,
    /// `value = slope · stored + inter` (NIfTI scl_slope / scl_inter).
    scale: Option<(f64, f64)>,
    /// Whether the stream is gzip: drained at the end so that its checksum and
    /// length trailer are verified.
    compressed: bool,
    next_slice: usize,
    buf: Vec<u8>,
    /// What converting the samples to f32 changed so far.
    rounding: super::Rounding,
    /// Values are text separated by white space (NRRD `encoding: ascii`).
    text: bool,
    /// Values read so far (text), for naming a bad one.
    values_read: u64,
    /// NaN means "no data" (`--nan empty`).
    nan_empty: bool,
    /// The scanner geometry the header gave (`VolumeSource::world`).
    world: Option<[[f64; 4]; 3]>,
    /// The time points of the file (a 4-D NIfTI), of which this reads one.
    time_points: usize,
}

impl RawSource {
    /// Wraps a stream positioned at the first sample. `info.voxel_type` is
    /// the stored type (see [`RawSource::with_scale`] for scaled data);
    /// `compressed` marks a gzip stream, read to its end after the last slice
    /// so that a damaged trailer is reported rather than ignored.
    pub fn from_reader(
        label: impl Into<String>,
        info: VolumeInfo,
        big_endian: bool,
        compressed: bool,
        reader: Box<dyn Read + Send>,
    ) -> Self {
        RawSource {
            stored: info.voxel_type,
            info,
            label: label.into(),
            reader,
            big_endian,
            scale: None,
            compressed,
            next_slice: 0,
            buf: Vec::new(),
            rounding: Default::default(),
            text: false,
            values_read: 0,
            nan_empty: false,
            world: None,
            time_points: 1,
        }
    }

    /// The volume's place in the scanner's patient space (LPS mm).
    pub fn with_world(mut self, world: Option<[[f64; 4]; 3]>) -> Self {
        self.world = world;
        self
    }

    /// The file holds `n` time points (`VolumeSource::time_points`).
    pub fn with_time_points(mut self, n: usize) -> Self {
        self.time_points = n;
        self
    }

    /// Applies `value = slope · stored + inter` to every sample and reports
    /// `reported` as the volume's voxel type.
    pub fn with_scale(mut self, slope: f64, inter: f64, reported: VoxelType) -> Self {
        self.scale = Some((slope, inter));
        self.info.voxel_type = reported;
        self
    }

    /// The stream holds values as text separated by white space.
    pub fn as_text(mut self) -> Self {
        self.text = true;
        self
    }

    /// One slice of text values, converted as binary samples are.
    fn read_text_slice(&mut self, k: usize, out: &mut [f32]) -> Result<()> {
        let nz = self.info.dims[2];
        let mut token = Vec::with_capacity(32);
        for o in out.iter_mut() {
            token.clear();
            let mut byte = [0u8; 1];
            loop {
                let n = self
                    .reader
                    .read(&mut byte)
                    .with_context(|| format!("{}: reading slice {k} of {nz}", self.label))?;
                if n == 0 {
                    break;
                }
                if byte[0].is_ascii_whitespace() {
                    if token.is_empty() {
                        continue;
                    }
                    break;
                }
                token.push(byte[0]);
                ensure!(
                    token.len() <= 64,
                    "{}: value {} is not a number (over 64 characters)",
                    self.label,
                    self.values_read
                );
            }
            if token.is_empty() {
                bail!(
                    "{}: the data ends in slice {k} of {nz} (z = 0..{}), after {} values: the file is truncated",
                    self.label,
                    nz - 1,
                    self.values_read
                );
            }
            let text = String::from_utf8_lossy(&token);
            let x: f64 = text.parse().map_err(|_| {
                anyhow::anyhow!(
                    "{}: value {} ('{text}') is not a number",
                    self.label,
                    self.values_read
                )
            })?;
            let (lo, hi) = self.stored.limits();
            ensure!(
                !x.is_finite() || (lo..=hi).contains(&x),
                "{}: value {} ({x}) is outside the range of {}",
                self.label,
                self.values_read,
                self.stored.name()
            );
            *o = x as f32;
            self.rounding.add_value(x, *o);
            self.values_read += 1;
        }
        Ok(())
    }

    fn read_slice(&mut self, k: usize, out: &mut [f32]) -> Result<()> {
        if self.text {
            self.read_text_slice(k, out)?;
            let first = k as u64 * self.info.slice_len() as u64;
            return check_finite(&self.label, self.info.dims, first, out, self.nan_empty);
        }
        let nz = self.info.dims[2];
        self.buf.resize(out.len() * self.stored.bytes(), 0);
        if let Err(e) = self.reader.read_exact(&mut self.buf) {
            if e.kind() == io::ErrorKind::UnexpectedEof {
                bail!(
                    "{}: the data ends in slice {k} of {nz} (z = 0..{}): the file is truncated",
                    self.label,
                    nz - 1
                );
            }
            bail!("{}: reading slice {k} of {nz}: {e}", self.label);
        }
        let r = decode_samples(&self.buf, self.stored, self.big_endian, out);
        self.rounding.add(r);
        if let Some((slope, inter)) = self.scale {
            for v in out.iter_mut() {
                *v = (slope * *v as f64 + inter) as f32;
            }
        }
        if self.stored.is_float() || self.stored.may_round() || self.scale.is_some() {
            let first = k as u64 * self.info.slice_len() as u64;
            check_finite(&self.label, self.info.dims, first, out, self.nan_empty)?;
        }
        Ok(())
    }
}

impl VolumeSource for RawSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn set_nan_empty(&mut self) {
        self.nan_empty = true;
    }

    fn world(&self) -> Option<[[f64; 4]; 3]> {
        self.world
    }

    fn time_points(&self) -> usize {
        self.time_points
    }

    fn conversion_note(&self) -> Option<String> {
        self.rounding.note_for(&self.label, self.stored)
    }

    fn read_slices(&mut self, out: &mut [f32]) -> Result<()> {
        let slice_len = self.info.slice_len();
        let nz = self.info.dims[2];
        ensure!(
            out.len() / slice_len * slice_len == out.len(),
            "{}: read_slices needs whole slices of {slice_len} values, got {}",
            self.label,
            out.len()
        );
        let count = out.len() / slice_len;
        ensure!(
            self.next_slice + count <= nz,
            "{}: read past the end of the volume (slices {}..{} of {nz})",
            self.label,
            self.next_slice,
            self.next_slice + count
        );
        for chunk in out.chunks_exact_mut(slice_len) {
            let k = self.next_slice;
            self.read_slice(k, chunk)?;
            self.next_slice += 1;
        }
        if self.compressed && self.next_slice == nz && count > 0 {
            // Reading to the end of the gzip stream checks its CRC and length.
            io::copy(&mut self.reader, &mut io::sink()).with_context(|| {
                format!(
                    "{}: gzip stream is corrupt after the last slice",
                    self.label
                )
            })?;
            self.buf = Vec::new();
        }
        Ok(())
    }
}

/// Checks an uncompressed data file's size against the header up front, so a
/// wrong `--dims` or `--type` is reported before any work is done.
/// `exact`: the data must end the file (raw, NRRD); otherwise it may be
/// followed by other bytes.
pub(crate) fn check_file_size(
    label: &str,
    info: &VolumeInfo,
    offset: u64,
    file_len: u64,
    exact: bool,
) -> Result<()> {
    // Saturating: a crafted offset (a NIfTI's vox_offset of 3e38) must not wrap.
    let expected = offset.saturating_add(info.source_bytes());
    if file_len == expected || (!exact && file_len > expected) {
        return Ok(());
    }
    let at_least = if exact { "" } else { "at least " };
    let shape = shape_text(info.dims, info.voxel_type);
    if offset > 0 {
        bail!(
            "{label}: expected {at_least}{expected} bytes ({offset}-byte header + {} for {shape}) \
             but the file has {file_len}",
            info.source_bytes()
        )
    }
    bail!("{label}: expected {at_least}{expected} bytes for {shape} but the file has {file_len}")
}

/// Opens a headerless raw volume. A name ending in `.gz` is decompressed on
/// the fly (its size cannot be checked up front; truncation is reported when
/// the missing slice is read).
pub fn open_raw(path: &Path, params: &RawParams) -> Result<RawSource> {
    let label = path.display().to_string();
    let info = VolumeInfo {
        dims: params.dims,
        spacing: params.spacing,
        voxel_type: params.voxel_type,
    };
    check_info(&label, &info, "dims", "spacing")?;
    let file = File::open(path).with_context(|| format!("{label}: cannot open"))?;
    let gz = path.to_string_lossy().to_lowercase().ends_with(".gz");
    let mut reader = BufReader::with_capacity(READ_BUFFER, file);
    if gz {
        let mut dec = MultiGzDecoder::new(reader);
        skip_bytes(&mut dec, params.byte_offset)
            .with_context(|| format!("{label}: skipping byte_offset {}", params.byte_offset))?;
        return Ok(RawSource::from_reader(
            label,
            info,
            params.big_endian,
            true,
            Box::new(dec),
        ));
    }
    let len = reader
        .get_ref()
        .metadata()
        .with_context(|| format!("{label}: cannot stat"))?
        .len();
    check_file_size(&label, &info, params.byte_offset, len, true)?;
    skip_bytes(&mut reader, params.byte_offset)
        .with_context(|| format!("{label}: skipping byte_offset {}", params.byte_offset))?;
    Ok(RawSource::from_reader(
        label,
        info,
        params.big_endian,
        false,
        Box::new(reader),
    ))
}

/// Reads and discards `n` bytes (works on decompressing streams, which
/// cannot seek); fewer bytes available is an error.
pub(crate) fn skip_bytes(r: &mut impl Read, n: u64) -> io::Result<()> {
    let skipped = io::copy(&mut r.take(n), &mut io::sink())?;
    if skipped < n {
        return Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!("the file ends after {skipped} of {n} bytes"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Volume;
    use std::io::Write;

    fn params(dims: [usize; 3], t: VoxelType, big: bool) -> RawParams {
        RawParams {
            dims,
            voxel_type: t,
            spacing: [0.5, 1.0, 2.0],
            byte_offset: 0,
            big_endian: big,
        }
    }

    #[test]
    fn big_endian_u16_and_i16_and_f32() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("be.raw");
        // 2×1×2 u16 big endian.
        std::fs::write(&p, [0x01, 0x02, 0xff, 0xfe, 0x00, 0x07, 0x80, 0x00]).unwrap();
        let mut src = open_raw(&p, &params([2, 1, 2], VoxelType::U16, true)).unwrap();
        assert_eq!(src.info().spacing, [0.5, 1.0, 2.0]);
        let v = Volume::read_all(&mut src).unwrap();
        assert_eq!(v.data, vec![258.0, 65534.0, 7.0, 32768.0]);

        let mut src = open_raw(&p, &params([2, 1, 2], VoxelType::I16, true)).unwrap();
        let v = Volume::read_all(&mut src).unwrap();
        assert_eq!(v.data, vec![258.0, -2.0, 7.0, -32768.0]);

        let q = dir.path().join("be32.raw");
        let mut bytes = Vec::new();
        for x in [1.5f32, -2.25] {
            bytes.extend_from_slice(&x.to_be_bytes());
        }
        std::fs::write(&q, &bytes).unwrap();
        let mut src = open_raw(&q, &params([1, 1, 2], VoxelType::F32, true)).unwrap();
        let v = Volume::read_all(&mut src).unwrap();
        assert_eq!(v.data, vec![1.5, -2.25]);
    }

    #[test]
    fn byte_offset_and_slice_by_slice() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("off.raw");
        let mut bytes = vec![9u8; 5];
        bytes.extend(0u8..24);
        std::fs::write(&p, &bytes).unwrap();
        let mut pr = params([4, 3, 2], VoxelType::U8, false);
        pr.byte_offset = 5;
        let mut src = open_raw(&p, &pr).unwrap();
        let mut s = vec![0f32; 12];
        src.read_slices(&mut s).unwrap();
        assert_eq!(s[0], 0.0);
        assert_eq!(s[11], 11.0);
        src.read_slices(&mut s).unwrap();
        assert_eq!(s[0], 12.0);
        let err = src.read_slices(&mut s).unwrap_err().to_string();
        assert!(
            err.contains("off.raw") && err.contains("past the end"),
            "{err}"
        );
    }

    #[test]
    fn wrong_size_is_reported_up_front() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("head.raw");
        std::fs::write(&p, vec![0u8; 1000]).unwrap();
        let err = open_raw(&p, &params([181, 217, 181], VoxelType::U8, false))
            .err()
            .unwrap()
            .to_string();
        assert_eq!(
            err,
            format!(
                "{}: expected 7109137 bytes for 181×217×181 u8 but the file has 1000",
                p.display()
            )
        );
    }

    #[test]
    fn zero_dims_and_bad_spacing_are_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("z.raw");
        std::fs::write(&p, [0u8; 4]).unwrap();
        let err = open_raw(&p, &params([2, 0, 2], VoxelType::U8, false))
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("z.raw") && err.contains("dims") && err.contains("axis 1 has size 0"),
            "{err}"
        );
        let mut pr = params([2, 2, 1], VoxelType::U8, false);
        pr.spacing = [1.0, -1.0, 1.0];
        let err = open_raw(&p, &pr).err().unwrap().to_string();
        assert!(
            err.contains("z.raw") && err.contains("spacing") && err.contains("axis 1"),
            "{err}"
        );
        pr.spacing = [1.0, 1.0, f64::NAN];
        let err = open_raw(&p, &pr).err().unwrap().to_string();
        assert!(
            err.contains("z.raw") && err.contains("spacing") && err.contains("NaN"),
            "{err}"
        );
    }

    #[test]
    fn truncated_stream_names_file_and_slice() {
        // The size check catches truncated plain files at open; a stream that
        // ends early (here: a file that shrinks after opening) is caught per slice.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("short.raw");
        std::fs::write(&p, vec![1u8; 2 * 2 * 3]).unwrap();
        let mut src = open_raw(&p, &params([2, 2, 3], VoxelType::U8, false)).unwrap();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&p)
            .unwrap()
            .set_len(6)
            .unwrap();
        let mut out = vec![0f32; 12];
        let err = src.read_slices(&mut out).unwrap_err().to_string();
        assert!(
            err.contains("short.raw") && err.contains("slice 1 of 3") && err.contains("truncated"),
            "{err}"
        );

        let err = open_raw(&p, &params([2, 2, 3], VoxelType::U8, false))
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("short.raw") && err.contains("expected 12 bytes"),
            "{err}"
        );
    }

    #[test]
    fn truncated_gzip_raw_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("vol.raw.gz");
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        let data: Vec<u8> = (0..4096u32)
            .map(|x| (x.wrapping_mul(2654435761) >> 24) as u8)
            .collect();
        enc.write_all(&data).unwrap();
        let gz = enc.finish().unwrap();
        std::fs::write(&p, &gz[..gz.len() / 2]).unwrap();
        let mut src = open_raw(&p, &params([16, 16, 16], VoxelType::U8, false)).unwrap();
        let err = Volume::read_all(&mut src).unwrap_err().to_string();
        assert!(err.contains("vol.raw.gz") && err.contains("slice"), "{err}");

        std::fs::write(&p, &gz).unwrap();
        let mut src = open_raw(&p, &params([16, 16, 16], VoxelType::U8, false)).unwrap();
        let v = Volume::read_all(&mut src).unwrap();
        assert_eq!(v.data[100], data[100] as f32);
    }

    #[test]
    fn nan_in_f32_raw_names_voxel() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nan.raw");
        let mut vals = [0f32; 2 * 2 * 2];
        vals[7] = f32::NAN; // (1,1,1)
        let bytes: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&p, bytes).unwrap();
        let mut src = open_raw(&p, &params([2, 2, 2], VoxelType::F32, false)).unwrap();
        let err = Volume::read_all(&mut src).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}: voxel (1,1,1) is NaN{}",
                p.display(),
                " (if NaN means \"no data\" here, import with --nan empty)"
            )
        );
        // --nan empty: NaN passes as no data.
        let mut src = open_raw(&p, &params([2, 2, 2], VoxelType::F32, false)).unwrap();
        src.set_nan_empty();
        let v = Volume::read_all(&mut src).unwrap();
        assert!(v.data[7].is_nan() && v.data[..7].iter().all(|x| *x == 0.0));
    }
}
