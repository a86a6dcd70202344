//! NIfTI-1 input (`.nii`, `.nii.gz`): the format of most MRI and many CT
//! volumes users have (docs/design.md "Data").
//!
//! The 348-byte header is parsed by the `nifti` crate (which also detects the
//! byte order); the voxels are streamed by [`RawSource`] from `vox_offset`,
//! so nothing holds the whole volume. Only the header's size and sample
//! fields are used: the volume is placed by the scene (docs/design.md "Volume
//! space"), not by the qform/sform.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use crate::volume::{VolumeInfo, VoxelType};
use anyhow::{bail, ensure, Context, Result};
use flate2::bufread::MultiGzDecoder;
use nifti::{Endianness, NiftiHeader};

use super::check_info;
use super::raw::{check_file_size, skip_bytes, RawSource, READ_BUFFER};

/// Size of a NIfTI-1 header; data of a single-file (`n+1`) volume starts at
/// `vox_offset` ≥ 352 (the header plus a 4-byte extension flag).
const HEADER_BYTES: usize = 348;
const MIN_VOX_OFFSET: u64 = 352;

/// NIfTI-1 datatype codes and names, for the supported mapping and for
/// naming the unsupported ones in errors.
fn datatype(code: i16) -> (Option<VoxelType>, &'static str) {
    match code {
        2 => (Some(VoxelType::U8), "uint8"),
        4 => (Some(VoxelType::I16), "int16"),
        16 => (Some(VoxelType::F32), "float32"),
        512 => (Some(VoxelType::U16), "uint16"),
        8 => (Some(VoxelType::I32), "int32"),
        64 => (Some(VoxelType::F64), "float64"),
        256 => (Some(VoxelType::I8), "int8"),
        768 => (Some(VoxelType::U32), "uint32"),
        1 => (None, "binary"),
        32 => (None, "complex64"),
        128 => (None, "rgb24"),
        1024 => (None, "int64"),
        1280 => (None, "uint64"),
        1536 => (None, "float128"),
        1792 => (None, "complex128"),
        2048 => (None, "complex256"),
        2304 => (None, "rgba32"),
        _ => (None, "unknown"),
    }
}

/// The voxel type reported for scaled data (`slope · stored + inter`).
///
/// With an integer slope and intercept every value is still an integer; the
/// first of u8, u16, i16 whose limits hold the scaled limits of the stored
/// type is reported (u8 with slope 1, inter −1024 → i16; u8 with inter 1000
/// → u16), so integer data keeps an exact integer type. When none does (i16
/// with inter −1024 can reach −33792), or the slope or intercept is
/// fractional, the values are reported as F32. The decision uses the stored
/// type's limits, not the data, because it is made before any voxel is read.
fn scaled_type(stored: VoxelType, slope: f64, inter: f64) -> VoxelType {
    let integer = |x: f64| x.fract() == 0.0 && x.abs() < 1e9;
    if stored.is_float() || stored.may_round() || !integer(slope) || !integer(inter) {
        return VoxelType::F32;
    }
    let (lo, hi) = stored.limits();
    let (a, b) = (slope * lo + inter, slope * hi + inter);
    let (lo, hi) = (a.min(b), a.max(b));
    [VoxelType::U8, VoxelType::U16, VoxelType::I16]
        .into_iter()
        .find(|t| {
            let (tl, th) = t.limits();
            tl <= lo && hi <= th
        })
        .unwrap_or(VoxelType::F32)
}

/// Opens a NIfTI-1 single-file volume (`.nii`, or gzip-compressed `.nii.gz`).
///
/// * Dimensions: `dim[0]` must be 3, or 4 with `dim[4]` time points (one
///   is read: `time`, else the first), or more with every extra axis of
///   size 1.
/// * Datatypes: uint8 (2), int16 (4), float32 (16), uint16 (512).
/// * Spacing: |pixdim[1..4]|; a pixdim of 0 (written by some tools for
///   "unknown") is read as 1, without a warning: the scene's `size` places
///   the volume anyway (docs/design.md "Volume space"). A non-finite pixdim is an
///   error.
/// * Scaling: if `scl_slope` ≠ 0 and (slope, inter) ≠ (1, 0), values are
///   `slope · stored + inter`; see [`scaled_type`] for the reported type.
pub fn open_nifti(path: &Path) -> Result<RawSource> {
    open_nifti_at(path, None)
}

/// [`open_nifti`] choosing time point `time` of a 4-D file.
pub fn open_nifti_at(path: &Path, time: Option<usize>) -> Result<RawSource> {
    let label = path.display().to_string();
    let file = File::open(path).with_context(|| format!("{label}: cannot open"))?;
    let gz = path.to_string_lossy().to_lowercase().ends_with(".gz");
    let file_len = file
        .metadata()
        .with_context(|| format!("{label}: cannot stat"))?
        .len();
    let buffered = BufReader::with_capacity(READ_BUFFER, file);
    let mut reader: Box<dyn Read + Send> = if gz {
        Box::new(MultiGzDecoder::new(buffered))
    } else {
        Box::new(buffered)
    };

    let mut raw_header = [0u8; HEADER_BYTES];
    reader
        .read_exact(&mut raw_header)
        .with_context(|| format!("{label}: cannot read the {HEADER_BYTES}-byte NIfTI header"))?;
    let sizeof_le =
        i32::from_le_bytes([raw_header[0], raw_header[1], raw_header[2], raw_header[3]]);
    let sizeof_be =
        i32::from_be_bytes([raw_header[0], raw_header[1], raw_header[2], raw_header[3]]);
    if sizeof_le == 540 || sizeof_be == 540 {
        bail!(
            "{label}: sizeof_hdr: 540 is a NIfTI-2 header, which is not supported (NIfTI-1 only)"
        );
    }
    ensure!(
        sizeof_le == 348 || sizeof_be == 348,
        "{label}: sizeof_hdr: {sizeof_le} is not 348 (not a NIfTI-1 file)"
    );
    let h = NiftiHeader::from_reader(&raw_header[..])
        .map_err(|e| anyhow::anyhow!("{label}: not a valid NIfTI-1 header ({e})"))?;
    ensure!(
        &h.magic == b"n+1\0",
        "{label}: magic: '{}' is a header/image pair (.hdr + .img), which is not supported (need a single .nii file)",
        String::from_utf8_lossy(&h.magic[..3])
    );

    // The header's dims are signed 16-bit: the reader's u16 turns a crafted
    // −5 into 65531, so they are read back as what the file says.
    let signed = h.dim.map(|d| d as i16);
    let used = signed[0].clamp(0, 7) as usize;
    if let Some(a) = (1..=used).find(|&a| signed[a] < 0) {
        bail!(
            "{label}: dim: dim[{a}] is {} (sizes must be positive)",
            signed[a]
        );
    }
    let ndim = h.dim[0] as usize;
    ensure!(
        (3..=7).contains(&ndim) && h.dim[5.min(ndim + 1)..=ndim].iter().all(|&d| d == 1),
        "{label}: dim: dim[0] = {} with sizes {:?} is not a 3-D volume or a time series of them",
        h.dim[0],
        &h.dim[1..=ndim.clamp(1, 7)]
    );
    let times = if ndim >= 4 {
        h.dim[4].max(1) as usize
    } else {
        1
    };
    let t = time.unwrap_or(0);
    ensure!(
        t < times,
        "{label}: --time {t}: dim[4] holds {times} time point(s), 0 to {}",
        times - 1
    );
    let dims = [h.dim[1] as usize, h.dim[2] as usize, h.dim[3] as usize];

    let (stored, type_name) = datatype(h.datatype);
    let Some(stored) = stored else {
        bail!(
            "{label}: datatype {} ({type_name}) is not supported (use int8, uint8, int16, uint16, int32, uint32, float32 or float64)",
            h.datatype
        );
    };

    let mut spacing = [1.0f64; 3];
    for (a, s) in spacing.iter_mut().enumerate() {
        let p = h.pixdim[a + 1] as f64;
        ensure!(p.is_finite(), "{label}: pixdim[{}] is {p}", a + 1);
        *s = if p == 0.0 { 1.0 } else { p.abs() };
    }

    let info = VolumeInfo {
        dims,
        spacing,
        voxel_type: stored,
    };
    check_info(&label, &info, "dim", "pixdim")?;

    let vox_offset = h.vox_offset as f64;
    ensure!(
        vox_offset.is_finite() && vox_offset >= 0.0,
        "{label}: vox_offset: {vox_offset} is not a byte offset"
    );
    // Some writers leave vox_offset at 0; the data then follows the header
    // and its 4-byte extension flag.
    let vox_offset = (vox_offset as u64).max(MIN_VOX_OFFSET);
    // Time point t's volume follows the t before it.
    let before = (t as u64)
        .checked_mul(info.voxel_count())
        .and_then(|n| n.checked_mul(stored.bytes() as u64))
        .and_then(|n| n.checked_add(vox_offset))
        .with_context(|| format!("{label}: dim: time point {t} lies beyond any file"))?;
    if !gz {
        check_file_size(
            &format!("{label}: dim, datatype, vox_offset"),
            &info,
            before,
            file_len,
            false,
        )?;
    }
    skip_bytes(&mut reader, before - HEADER_BYTES as u64).with_context(|| {
        format!("{label}: vox_offset, dim[4]: cannot reach time point {t}'s data at byte {before}")
    })?;

    let big_endian = h.endianness == Endianness::Big;
    let world = world(&h, spacing);
    let mut src = RawSource::from_reader(label, info, big_endian, gz, reader)
        .with_world(world)
        .with_time_points(times);
    let (slope, inter) = (h.scl_slope as f64, h.scl_inter as f64);
    if slope.is_finite() && inter.is_finite() && slope != 0.0 && !(slope == 1.0 && inter == 0.0) {
        src = src.with_scale(slope, inter, scaled_type(stored, slope, inter));
    }
    Ok(src)
}

/// The scanner geometry of the header (`VolumeSource::world`): the sform
/// where `sform_code` > 0, else the qform where `qform_code` > 0 (the
/// NIfTI-1 standard's methods 3 and 2), turned from NIfTI's RAS into LPS;
/// `None` without either, or where one is not finite or flattens the
/// volume.
fn world(h: &NiftiHeader, spacing: [f64; 3]) -> Option<[[f64; 4]; 3]> {
    // Voxel (i, j, k)'s centre: first + i·steps[0] + j·steps[1] + k·steps[2] (RAS).
    let (first, steps): ([f64; 3], [[f64; 3]; 3]) = if h.sform_code > 0 {
        let rows = [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(f64::from));
        (
            [rows[0][3], rows[1][3], rows[2][3]],
            std::array::from_fn(|a| [rows[0][a], rows[1][a], rows[2][a]]),
        )
    } else if h.qform_code > 0 {
        let [b, c, d] = [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from);
        let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
        let r = [
            [
                a * a + b * b - c * c - d * d,
                2.0 * (b * c - a * d),
                2.0 * (b * d + a * c),
            ],
            [
                2.0 * (b * c + a * d),
                a * a + c * c - b * b - d * d,
                2.0 * (c * d - a * b),
            ],
            [
                2.0 * (b * d - a * c),
                2.0 * (c * d + a * b),
                a * a + d * d - c * c - b * b,
            ],
        ];
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let scale = [spacing[0], spacing[1], qfac * spacing[2]];
        (
            [h.quatern_x, h.quatern_y, h.quatern_z].map(f64::from),
            std::array::from_fn(|a| std::array::from_fn(|row| r[row][a] * scale[a])),
        )
    } else {
        return None;
    };
    let lps = |v: [f64; 3]| [-v[0], -v[1], v[2]];
    let (first, steps) = (lps(first), steps.map(lps));
    super::world_from(first, steps, spacing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Volume, VolumeSource};
    use std::io::Write;

    /// A minimal NIfTI-1 header (native little endian, or big endian).
    fn header(
        dims: [u16; 3],
        datatype: i16,
        bitpix: i16,
        pixdim: [f32; 3],
        slope: f32,
        inter: f32,
        big: bool,
    ) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        let put = |h: &mut Vec<u8>, at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
        macro_rules! w {
            ($at:expr, $v:expr) => {
                put(
                    &mut h,
                    $at,
                    &if big {
                        $v.to_be_bytes()
                    } else {
                        $v.to_le_bytes()
                    },
                )
            };
        }
        w!(0, 348i32);
        let dim: [u16; 8] = [3, dims[0], dims[1], dims[2], 1, 1, 1, 1];
        for (i, d) in dim.iter().enumerate() {
            w!(40 + 2 * i, *d);
        }
        w!(70, datatype);
        w!(72, bitpix);
        let pd = [1.0f32, pixdim[0], pixdim[1], pixdim[2], 0.0, 0.0, 0.0, 0.0];
        for (i, p) in pd.iter().enumerate() {
            w!(76 + 4 * i, *p);
        }
        w!(108, 352.0f32);
        w!(112, slope);
        w!(116, inter);
        put(&mut h, 344, b"n+1\0");
        h
    }

    fn write(path: &Path, bytes: &[u8]) {
        if path.to_string_lossy().ends_with(".gz") {
            let mut enc = flate2::write::GzEncoder::new(
                File::create(path).unwrap(),
                flate2::Compression::fast(),
            );
            enc.write_all(bytes).unwrap();
            enc.finish().unwrap();
        } else {
            std::fs::write(path, bytes).unwrap();
        }
    }

    /// Where voxel (i, j, k)'s centre lands under `w` (volume space: the
    /// centre at (i + ½)·s).
    fn centre(w: &[[f64; 4]; 3], ijk: [f64; 3], s: [f64; 3]) -> [f64; 3] {
        let p: [f64; 3] = std::array::from_fn(|a| (ijk[a] + 0.5) * s[a]);
        std::array::from_fn(|r| w[r][0] * p[0] + w[r][1] * p[1] + w[r][2] * p[2] + w[r][3])
    }

    /// NIfTI-1's methods 3 (sform) and 2 (qform), turned from RAS to LPS;
    /// none without a code.
    #[test]
    fn the_sform_or_the_qform_places_the_volume_in_lps() {
        let sp = [0.5, 0.5, 2.0];
        let mut h = NiftiHeader {
            sform_code: 0,
            qform_code: 0,
            ..Default::default()
        };
        assert_eq!(world(&h, sp), None);
        h.sform_code = 1;
        h.srow_x = [-0.5, 0.0, 0.0, 90.0];
        h.srow_y = [0.0, 0.5, 0.0, -126.0];
        h.srow_z = [0.0, 0.0, 2.0, -72.0];
        let w = world(&h, sp).unwrap();
        for ijk in [[0.0, 0.0, 0.0], [3.0, 5.0, 7.0]] {
            let ras = [
                -0.5 * ijk[0] + 90.0,
                0.5 * ijk[1] - 126.0,
                2.0 * ijk[2] - 72.0,
            ];
            let lps = centre(&w, ijk, sp);
            let want = [-ras[0], -ras[1], ras[2]];
            assert!(
                (0..3).all(|k| (lps[k] - want[k]).abs() < 1e-9),
                "{lps:?} {want:?}"
            );
        }
        // The qform: 180° about z (quaternion (0, 0, 1)), qfac −1.
        h.sform_code = 0;
        h.qform_code = 1;
        h.quatern_d = 1.0;
        h.quatern_x = 10.0;
        h.quatern_y = 20.0;
        h.quatern_z = 30.0;
        h.pixdim = [-1.0, 0.5, 0.5, 2.0, 0.0, 0.0, 0.0, 0.0];
        let w = world(&h, sp).unwrap();
        let ijk = [2.0, 4.0, 6.0];
        let ras = [
            10.0 - 0.5 * ijk[0],
            20.0 - 0.5 * ijk[1],
            30.0 - 2.0 * ijk[2],
        ];
        let lps = centre(&w, ijk, sp);
        let want = [-ras[0], -ras[1], ras[2]];
        assert!(
            (0..3).all(|k| (lps[k] - want[k]).abs() < 1e-9),
            "{lps:?} {want:?}"
        );
        // A flattening sform is no geometry.
        h.sform_code = 1;
        h.srow_z = [0.0; 4];
        assert_eq!(world(&h, sp), None);
    }

    #[test]
    fn reads_int16_big_endian_and_gzip() {
        let dir = tempfile::tempdir().unwrap();
        let vals: Vec<i16> = vec![-1000, 0, 7, 32767, -32768, 12, 13, 14];
        for (name, big) in [("a.nii", false), ("b.nii", true), ("c.nii.gz", false)] {
            let mut bytes = header([2, 2, 2], 4, 16, [0.5, -0.75, 0.0], 0.0, 0.0, big);
            for v in &vals {
                bytes.extend_from_slice(&if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
            let p = dir.path().join(name);
            write(&p, &bytes);
            let mut src = super::super::open(&p, None).unwrap();
            // pixdim −0.75 → 0.75 (absolute), 0 → 1.
            assert_eq!(src.info().spacing, [0.5, 0.75, 1.0]);
            assert_eq!(src.info().voxel_type, VoxelType::I16);
            let v = Volume::read_all(&mut *src).unwrap();
            let want: Vec<f32> = vals.iter().map(|&x| x as f32).collect();
            assert_eq!(v.data, want, "{name}");
        }
    }

    #[test]
    fn scaling_changes_values_and_type() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.nii");
        let mut bytes = header([2, 1, 1], 2, 8, [1.0; 3], 2.0, -1024.0, false);
        bytes.extend_from_slice(&[0, 255]);
        write(&p, &bytes);
        let mut src = open_nifti(&p).unwrap();
        assert_eq!(src.info().voxel_type, VoxelType::I16);
        let mut out = [0f32; 2];
        src.read_slices(&mut out).unwrap();
        assert_eq!(out, [-1024.0, -514.0]);

        let mut bytes = header([2, 1, 1], 2, 8, [1.0; 3], 0.5, 0.25, false);
        bytes.extend_from_slice(&[3, 255]);
        write(&p, &bytes);
        let mut src = open_nifti(&p).unwrap();
        assert_eq!(src.info().voxel_type, VoxelType::F32);
        src.read_slices(&mut out).unwrap();
        assert_eq!(out, [1.75, 127.75]);

        // (1, 0) and slope 0 mean "no scaling".
        for (slope, inter) in [(1.0, 0.0), (0.0, 5.0)] {
            let mut bytes = header([2, 1, 1], 2, 8, [1.0; 3], slope, inter, false);
            bytes.extend_from_slice(&[3, 255]);
            write(&p, &bytes);
            let mut src = open_nifti(&p).unwrap();
            assert_eq!(src.info().voxel_type, VoxelType::U8);
            src.read_slices(&mut out).unwrap();
            assert_eq!(out, [3.0, 255.0]);
        }
        assert_eq!(scaled_type(VoxelType::I16, 1.0, -1024.0), VoxelType::F32);
        assert_eq!(scaled_type(VoxelType::U8, 1.0, 1000.0), VoxelType::U16);
        assert_eq!(scaled_type(VoxelType::U16, 1.0, 0.0), VoxelType::U16);
    }

    #[test]
    fn bad_inputs_name_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.nii");
        let case = |bytes: Vec<u8>| {
            write(&p, &bytes);
            open_nifti(&p).err().expect("must fail").to_string()
        };
        let err = case(header([2, 2, 2], 1024, 64, [1.0; 3], 0.0, 0.0, false));
        assert!(
            err.contains("bad.nii") && err.contains("datatype 1024 (int64)"),
            "{err}"
        );

        let mut h = header([2, 2, 2], 2, 8, [1.0; 3], 0.0, 0.0, false);
        h[40..42].copy_from_slice(&2u16.to_le_bytes());
        let err = case(h);
        assert!(
            err.contains("bad.nii") && err.contains("dim[0] = 2"),
            "{err}"
        );

        let mut h = header([2, 0, 2], 2, 8, [1.0; 3], 0.0, 0.0, false);
        h.extend_from_slice(&[0; 8]);
        let err = case(h);
        assert!(
            err.contains("bad.nii") && err.contains("dim: axis 1 has size 0"),
            "{err}"
        );

        let mut h = header([2, 2, 2], 2, 8, [1.0, f32::NAN, 1.0], 0.0, 0.0, false);
        h.extend_from_slice(&[0; 8]);
        let err = case(h);
        assert!(
            err.contains("bad.nii") && err.contains("pixdim[2] is NaN"),
            "{err}"
        );

        let mut h = header([2, 2, 2], 2, 8, [1.0; 3], 0.0, 0.0, false);
        h.extend_from_slice(&[0; 5]);
        let err = case(h);
        assert!(
            err.contains("bad.nii")
                && err.contains("expected at least 360 bytes")
                && err.contains("has 357"),
            "{err}"
        );

        let mut h = header([2, 2, 2], 2, 8, [1.0; 3], 0.0, 0.0, false);
        h[344..348].copy_from_slice(b"ni1\0");
        let err = case(h);
        assert!(err.contains("bad.nii") && err.contains("magic"), "{err}");

        let err = case(vec![7u8; 400]);
        assert!(
            err.contains("bad.nii") && err.contains("sizeof_hdr"),
            "{err}"
        );
    }

    #[test]
    fn nan_and_truncated_gzip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.nii.gz");
        let mut bytes = header([2, 2, 2], 16, 32, [1.0; 3], 0.0, 0.0, false);
        for x in 0..8 {
            let v = if x == 5 { f32::INFINITY } else { x as f32 };
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        write(&p, &bytes);
        let mut src = open_nifti(&p).unwrap();
        let err = Volume::read_all(&mut src).unwrap_err().to_string();
        assert_eq!(err, format!("{}: voxel (1,0,1) is +infinity", p.display()));

        let mut bytes = header([64, 64, 4], 2, 8, [1.0; 3], 0.0, 0.0, false);
        bytes.extend((0..64 * 64 * 4u32).map(|x| (x.wrapping_mul(2654435761) >> 24) as u8));
        write(&p, &bytes);
        let gz = std::fs::read(&p).unwrap();
        std::fs::write(&p, &gz[..gz.len() * 3 / 4]).unwrap();
        let mut src = open_nifti(&p).unwrap();
        let err = Volume::read_all(&mut src).unwrap_err().to_string();
        assert!(err.contains("f.nii.gz") && err.contains("slice"), "{err}");
    }

    /// Colin27 (ch2), the MRI template shipped with MRIcron: 181×217×181 u8,
    /// 1 mm voxels, gzip-compressed.
    #[test]
    fn colin27_opens() {
        let path = Path::new("/usr/share/mricron/templates/ch2.nii.gz");
        if !path.exists() {
            println!("skipping colin27_opens: {} is missing", path.display());
            return;
        }
        let mut src = super::super::open(path, None).unwrap();
        let info = src.info().clone();
        assert_eq!(info.dims, [181, 217, 181]);
        assert_eq!(info.spacing, [1.0, 1.0, 1.0]);
        assert_eq!(info.voxel_type, VoxelType::U8);
        let mut buf = vec![0f32; info.slice_len() * 20];
        let (mut lo, mut hi, mut sum) = (f32::INFINITY, f32::NEG_INFINITY, 0f64);
        let mut k = 0;
        while k < info.dims[2] {
            let n = 20.min(info.dims[2] - k);
            let chunk = &mut buf[..n * info.slice_len()];
            src.read_slices(chunk).unwrap();
            for &v in chunk.iter() {
                lo = lo.min(v);
                hi = hi.max(v);
                sum += v as f64;
            }
            k += n;
        }
        let mean = sum / info.voxel_count() as f64;
        assert_eq!(lo, 0.0);
        assert!(hi > 100.0 && hi <= 255.0, "max {hi}");
        assert!(mean > 5.0 && mean < 150.0, "mean {mean}");
        assert!(src.read_slices(&mut buf[..info.slice_len()]).is_err());
    }
}
