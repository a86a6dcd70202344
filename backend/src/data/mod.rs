//! Volume input: raw, NRRD, NIfTI, DICOM and TIFF readers, procedural
//! volumes, and transfer-function presets from ParaView and 3D Slicer
//! ([`presets`]).
//!
//! Every reader is a [`VolumeSource`]: it reads z-slices on demand, in
//! increasing z, through a buffered (and, for gzip, decompressing) stream, so a
//! volume larger than RAM can be imported (docs/design.md "Data": "It must
//! stream"). Values are handed on as `f32` data values in the volume-space
//! layout of docs/design.md ("Volume space"): x fastest, then y, then z.
//!
//! Errors name the file and the field or voxel at fault, because the person
//! reading them is usually looking at a header in a text editor.

mod contain;
pub use contain::{install_hook, CappedAlloc};
pub mod dicom;
mod dicom_lengths;
pub mod nifti;
pub mod nrrd;
pub mod presets;
pub mod raw;
pub mod synth;
pub mod tiff;
pub mod zarr;

use std::path::Path;

use crate::volume::{VolumeInfo, VolumeSource, VoxelType};
use anyhow::{bail, Result};

pub use self::nrrd::NrrdWriter;
pub use self::raw::RawSource;
pub use self::synth::{synth_value, write_synth, write_thick_ct, SynthKind};

/// How to read a headerless raw volume (`parallax import x.raw --dims …
/// --type … --spacing …`, docs/design.md "Command line"): the header a raw file
/// does not have.
#[derive(Clone, Debug, PartialEq)]
pub struct RawParams {
    /// Voxels along x, y, z (x fastest in the file).
    pub dims: [usize; 3],
    /// Sample type of the file.
    pub voxel_type: VoxelType,
    /// Voxel spacing in the data's length unit.
    pub spacing: [f64; 3],
    /// Bytes to skip at the start of the file (an unknown header).
    pub byte_offset: u64,
    /// Byte order of multi-byte samples.
    pub big_endian: bool,
}

/// What a source may need beyond its path.
#[derive(Clone, Debug, Default)]
pub struct InputOptions {
    /// A headerless raw file's dims, type and spacing.
    pub raw: Option<RawParams>,
    /// Which DICOM series of a folder (UID, or its number in the listing).
    pub series: Option<String>,
    /// Voxel spacing of a TIFF stack (overrides its metadata).
    pub spacing: Option<[f64; 3]>,
    /// NaN in float input means "no data" (`--nan empty`) instead of an
    /// error.
    pub nan_empty: bool,
    /// Which level, channel and time point of an OME-Zarr image.
    pub zarr: zarr::ZarrSelect,
}

/// Opens a volume for streaming: a folder of DICOM slices or of TIFFs, a
/// multi-page `.tif`/`.tiff`, or a file [`open`] reads.
pub fn open_with(path: &Path, opts: &InputOptions) -> Result<Box<dyn VolumeSource + Send>> {
    let mut src = open_any(path, opts)?;
    if opts.nan_empty {
        src.set_nan_empty();
    }
    Ok(src)
}

fn open_any(path: &Path, opts: &InputOptions) -> Result<Box<dyn VolumeSource + Send>> {
    if opts.raw.is_none() {
        if zarr::is_zarr(path) {
            return Ok(Box::new(zarr::open_zarr(path, &opts.zarr, opts.spacing)?));
        }
        let lower = path.to_string_lossy().to_lowercase();
        if lower.ends_with(".nii") || lower.ends_with(".nii.gz") {
            if opts.zarr.level.is_some() || opts.zarr.channel.is_some() {
                bail!(
                    "{}: --level and --channel choose within an OME-Zarr image, and this is a NIfTI file",
                    path.display()
                );
            }
            return Ok(Box::new(nifti::open_nifti_at(path, opts.zarr.time)?));
        }
        if opts.zarr != zarr::ZarrSelect::default() {
            bail!(
                "{}: --level, --channel and --time choose within an OME-Zarr image (--time also a 4-D NIfTI's time point), and this is neither",
                path.display()
            );
        }
        if path.is_dir() {
            let lower = path.to_string_lossy().to_lowercase();
            if lower.trim_end_matches('/').ends_with(".zarr") {
                bail!(
                    "{}: a .zarr folder without Zarr metadata (zarr.json for Zarr v3; .zgroup, .zattrs or .zarray for v2)",
                    path.display()
                );
            }
            let has_tiff = !tiff::stack_files(path)?.is_empty();
            return if has_tiff {
                Ok(Box::new(tiff::open_tiff(path, opts.spacing)?))
            } else {
                Ok(Box::new(dicom::open_dicom(path, opts.series.as_deref())?))
            };
        }
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_lowercase())
            .unwrap_or_default();
        if name.ends_with(".tif") || name.ends_with(".tiff") {
            return Ok(Box::new(tiff::open_tiff(path, opts.spacing)?));
        }
        if name.ends_with(".dcm") {
            bail!(
                "{}: a single DICOM slice; import the folder that holds the series",
                path.display()
            );
        }
    }
    open(path, opts.raw.clone())
}

/// Opens a volume file for streaming, choosing the reader by extension:
/// `.nrrd` / `.nhdr` (NRRD), `.nii` / `.nii.gz` (NIfTI-1), `.raw`. When `raw`
/// parameters are given the file is read as raw whatever its name (a name
/// ending in `.gz` is decompressed on the fly).
pub fn open(path: &Path, raw: Option<RawParams>) -> Result<Box<dyn VolumeSource + Send>> {
    if let Some(params) = raw {
        return Ok(Box::new(raw::open_raw(path, &params)?));
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
        Ok(Box::new(nrrd::open_nrrd(path)?))
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        Ok(Box::new(nifti::open_nifti(path)?))
    } else if name.ends_with(".raw") || name.ends_with(".raw.gz") {
        bail!(
            "{}: a raw volume has no header; give its dims, type and spacing \
             (--dims X,Y,Z --type u8|i8|u16|i16|u32|i32|f32|f64 --spacing sx,sy,sz)",
            path.display()
        )
    } else {
        bail!(
            "{}: unknown volume format (expected .nrrd, .nhdr, .nii, .nii.gz, .raw, .tif, .tiff, or a folder of DICOM or TIFF slices)",
            path.display()
        )
    }
}

/// Hands the whole z-slices of `out` to `read`, one at a time with its z
/// (from `*next`, which it advances), for sources that decode a slice at a
/// time (a DICOM file, a TIFF page): a partial slice, or one past the last,
/// is an error naming `label`.
pub(crate) fn slice_by_slice(
    label: &str,
    info: &VolumeInfo,
    next: &mut usize,
    out: &mut [f32],
    mut read: impl FnMut(usize, &mut [f32]) -> Result<()>,
) -> Result<()> {
    let n = info.slice_len();
    anyhow::ensure!(
        out.len().is_multiple_of(n),
        "{label}: read_slices needs whole slices"
    );
    for chunk in out.chunks_mut(n) {
        anyhow::ensure!(*next < info.dims[2], "{label}: reading past the last slice");
        read(*next, chunk)?;
        *next += 1;
    }
    Ok(())
}

/// "181×217×181 u8": how messages describe a volume's shape.
pub(crate) fn shape_text(dims: [usize; 3], voxel_type: VoxelType) -> String {
    format!("{}×{}×{} {}", dims[0], dims[1], dims[2], voxel_type.name())
}

/// Checks what every reader must guarantee before handing out a
/// [`VolumeInfo`]: no zero dimension, and a finite positive spacing (the
/// volume-space box [0, N·s] of docs/design.md must be a real box). `dims_field`
/// and `spacing_field` name where the values came from in the file.
use crate::store::reader::MAX_DIM;

pub(crate) fn check_info(
    label: &str,
    info: &VolumeInfo,
    dims_field: &str,
    spacing_field: &str,
) -> Result<()> {
    for (axis, &n) in info.dims.iter().enumerate() {
        if n == 0 {
            bail!("{label}: {dims_field}: axis {axis} has size 0");
        }
        // The one cap every importer checks before it allocates or loops:
        // the largest side a database may hold (the store's reader refuses
        // more), so that no octree layout or memory estimate can wrap.
        if n > MAX_DIM {
            bail!("{label}: {dims_field}: axis {axis} has {n} voxels; a volume may have at most {MAX_DIM} (2^24) along an axis");
        }
    }
    for (axis, &s) in info.spacing.iter().enumerate() {
        if s.is_nan() {
            bail!("{label}: {spacing_field}: spacing of axis {axis} is NaN");
        }
        if s <= 0.0 || s.is_infinite() {
            bail!("{label}: {spacing_field}: spacing of axis {axis} is {s} (must be positive and finite)");
        }
    }
    let bytes = info
        .dims
        .iter()
        .try_fold(info.voxel_type.bytes() as u64, |acc, &n| {
            acc.checked_mul(n as u64)
        });
    if bytes.is_none() {
        bail!("{label}: {dims_field}: the volume is too large to address");
    }
    Ok(())
}

/// Converts packed samples of `voxel_type` in the given byte order to data
/// values. `bytes.len()` must be `out.len() · voxel_type.bytes()`.
pub(crate) fn decode_samples(
    bytes: &[u8],
    voxel_type: VoxelType,
    big_endian: bool,
    out: &mut [f32],
) -> Rounding {
    debug_assert_eq!(bytes.len(), out.len() * voxel_type.bytes());
    let mut r = Rounding::default();
    macro_rules! wide {
        ($t:ty, $n:literal) => {
            for (o, c) in out.iter_mut().zip(bytes.chunks_exact($n)) {
                let a: [u8; $n] = c.try_into().unwrap();
                let x = if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                } as f64;
                *o = x as f32;
                r.note(x, *o);
            }
        };
    }
    match voxel_type {
        VoxelType::I8 => {
            for (o, &b) in out.iter_mut().zip(bytes) {
                *o = b as i8 as f32;
            }
        }
        VoxelType::I32 => wide!(i32, 4),
        VoxelType::U32 => wide!(u32, 4),
        VoxelType::F64 => wide!(f64, 8),
        VoxelType::U8 => {
            for (o, &b) in out.iter_mut().zip(bytes) {
                *o = b as f32;
            }
        }
        VoxelType::U16 => {
            for (o, c) in out.iter_mut().zip(bytes.chunks_exact(2)) {
                let a = [c[0], c[1]];
                *o = if big_endian {
                    u16::from_be_bytes(a)
                } else {
                    u16::from_le_bytes(a)
                } as f32;
            }
        }
        VoxelType::I16 => {
            for (o, c) in out.iter_mut().zip(bytes.chunks_exact(2)) {
                let a = [c[0], c[1]];
                *o = if big_endian {
                    i16::from_be_bytes(a)
                } else {
                    i16::from_le_bytes(a)
                } as f32;
            }
        }
        VoxelType::F32 => {
            for (o, c) in out.iter_mut().zip(bytes.chunks_exact(4)) {
                let a = [c[0], c[1], c[2], c[3]];
                *o = if big_endian {
                    f32::from_be_bytes(a)
                } else {
                    f32::from_le_bytes(a)
                };
            }
        }
    }
    r
}

/// What converting samples to `f32` changed: how many values, and the
/// largest change (data units). NaN and ±Inf are not counted (they are
/// refused, naming the voxel, by the reader).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rounding {
    pub changed: u64,
    pub max_change: f64,
}

impl Rounding {
    fn note(&mut self, exact: f64, stored: f32) {
        let d = (stored as f64 - exact).abs();
        if d > 0.0 && d.is_finite() {
            self.changed += 1;
            self.max_change = self.max_change.max(d);
        }
    }

    /// Counts one value read exactly as `exact` and stored as `stored`.
    pub fn add_value(&mut self, exact: f64, stored: f32) {
        self.note(exact, stored);
    }

    pub fn add(&mut self, o: Rounding) {
        self.changed += o.changed;
        self.max_change = self.max_change.max(o.max_change);
    }

    /// The note a reader gives after a whole volume.
    pub fn note_for(&self, label: &str, t: VoxelType) -> Option<String> {
        (self.changed > 0).then(|| {
            format!(
                "{label}: {} {} values were rounded to the nearest 32-bit float (largest change {:.3e})",
                self.changed,
                t.name(),
                self.max_change
            )
        })
    }
}

/// Converts data values to packed samples of `voxel_type` (appended to
/// `out`), rounding to the nearest integer and clamping to the type's limits
/// for the integer types. Values must be finite (checked by the caller).
pub(crate) fn encode_samples(
    values: &[f32],
    voxel_type: VoxelType,
    big_endian: bool,
    out: &mut Vec<u8>,
) {
    out.reserve(values.len() * voxel_type.bytes());
    let (lo, hi) = voxel_type.limits();
    let int = |v: f32| (v as f64).round().clamp(lo, hi);
    // Each value converted by `$conv`, then written in the byte order asked.
    macro_rules! put {
        ($conv:expr) => {
            for &v in values {
                let x = $conv(v);
                out.extend_from_slice(&if big_endian {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                });
            }
        };
    }
    match voxel_type {
        VoxelType::U8 => out.extend(values.iter().map(|&v| int(v) as u8)),
        VoxelType::I8 => out.extend(values.iter().map(|&v| int(v) as i8 as u8)),
        VoxelType::U16 => put!(|v| int(v) as u16),
        VoxelType::I16 => put!(|v| int(v) as i16),
        VoxelType::U32 => put!(|v| int(v) as u32),
        VoxelType::I32 => put!(|v| int(v) as i32),
        VoxelType::F32 => put!(|v: f32| v),
        VoxelType::F64 => put!(|v: f32| v as f64),
    }
}

/// Rejects NaN and infinities: a non-finite data value would poison every
/// brick range, average and pre-integrated table downstream, so float input
/// is checked as it is read (docs/design.md "Data", `VolumeSource` contract).
/// `first` is the linear index (x fastest) of `values[0]` in the volume.
pub(crate) fn check_finite(
    label: &str,
    dims: [usize; 3],
    first: u64,
    values: &[f32],
    nan_is_no_data: bool,
) -> Result<()> {
    let bad = |v: &f32| !(v.is_finite() || nan_is_no_data && v.is_nan());
    if let Some(pos) = values.iter().position(bad) {
        let v = values[pos];
        let idx = first + pos as u64;
        let nx = dims[0] as u64;
        let ny = dims[1] as u64;
        let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
        let what = if v.is_nan() {
            "NaN"
        } else if v > 0.0 {
            "+infinity"
        } else {
            "-infinity"
        };
        let hint = if v.is_nan() {
            " (if NaN means \"no data\" here, import with --nan empty)"
        } else {
            ""
        };
        bail!("{label}: voxel ({i},{j},{k}) is {what}{hint}");
    }
    Ok(())
}

/// A source's values made labels by thresholds (`parallax import
/// --labels-from-thresholds`): a voxel's label is the number of thresholds
/// at or below its value (0 below the first), NaN stays no data. A label
/// volume made from the volume itself, for a layer that names its tissues.
pub struct Thresholded {
    inner: Box<dyn VolumeSource + Send>,
    thresholds: Vec<f32>,
    info: VolumeInfo,
}

impl Thresholded {
    /// `thresholds` must be finite and strictly ascending (at most 255).
    pub fn new(inner: Box<dyn VolumeSource + Send>, thresholds: Vec<f32>) -> Result<Self> {
        if thresholds.is_empty()
            || thresholds.len() > 255
            || thresholds.iter().any(|t| !t.is_finite())
            || thresholds.windows(2).any(|w| w[0] >= w[1])
        {
            bail!(
                "--labels-from-thresholds {thresholds:?}: give 1 to 255 finite thresholds in ascending order"
            );
        }
        let info = VolumeInfo {
            voxel_type: VoxelType::U8,
            ..inner.info().clone()
        };
        Ok(Thresholded {
            inner,
            thresholds,
            info,
        })
    }
}

/// The scanner geometry of a volume whose voxel (i, j, k) has its centre
/// at `first + i·steps[0] + j·steps[1] + k·steps[2]` (LPS mm; `steps[a]`
/// one voxel along axis a, its length the spacing): the affine map from
/// volume space (data units from the first voxel's corner: voxel centres at
/// (i + ½)·s) to LPS, three rows `[a, b, c, t]` (`VolumeSource::world`);
/// `None` where a value is not finite or the steps flatten the volume.
pub fn world_from(
    first: [f64; 3],
    steps: [[f64; 3]; 3],
    spacing: [f64; 3],
) -> Option<[[f64; 4]; 3]> {
    let w: [[f64; 4]; 3] = std::array::from_fn(|r| {
        let m: [f64; 3] = std::array::from_fn(|a| steps[a][r] / spacing[a]);
        let t = first[r] - 0.5 * (steps[0][r] + steps[1][r] + steps[2][r]);
        [m[0], m[1], m[2], t]
    });
    let ok = w.as_flattened().iter().all(|x| x.is_finite())
        && crate::loader::Affine::from_rows(&w).inverse().is_some();
    ok.then_some(w)
}

impl VolumeSource for Thresholded {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, out: &mut [f32]) -> Result<()> {
        self.inner.read_slices(out)?;
        for v in out.iter_mut() {
            if !v.is_nan() {
                *v = self.thresholds.partition_point(|t| t <= v) as f32;
            }
        }
        Ok(())
    }

    fn world(&self) -> Option<[[f64; 4]; 3]> {
        self.inner.world()
    }

    fn describe(&self) -> Option<String> {
        let own = format!("labels by thresholds {:?}", self.thresholds);
        Some(match self.inner.describe() {
            Some(d) => format!("{d}; {own}"),
            None => own,
        })
    }

    fn set_nan_empty(&mut self) {
        self.inner.set_nan_empty();
    }

    fn buffer_bytes(&self) -> u64 {
        self.inner.buffer_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn encode_decode_round_trip_and_clamp() {
        let values = [-3.0f32, -0.4, 0.5, 1.49, 254.6, 300.0, 70000.0, -40000.0];
        for big in [false, true] {
            let mut bytes = Vec::new();
            encode_samples(&values, VoxelType::U8, big, &mut bytes);
            let mut back = [0f32; 8];
            decode_samples(&bytes, VoxelType::U8, big, &mut back);
            assert_eq!(back, [0.0, 0.0, 1.0, 1.0, 255.0, 255.0, 255.0, 0.0]);

            bytes.clear();
            encode_samples(&values, VoxelType::U16, big, &mut bytes);
            decode_samples(&bytes, VoxelType::U16, big, &mut back);
            assert_eq!(back, [0.0, 0.0, 1.0, 1.0, 255.0, 300.0, 65535.0, 0.0]);

            bytes.clear();
            encode_samples(&values, VoxelType::I16, big, &mut bytes);
            decode_samples(&bytes, VoxelType::I16, big, &mut back);
            assert_eq!(
                back,
                [-3.0, -0.0, 1.0, 1.0, 255.0, 300.0, 32767.0, -32768.0]
            );

            bytes.clear();
            encode_samples(&values, VoxelType::F32, big, &mut bytes);
            decode_samples(&bytes, VoxelType::F32, big, &mut back);
            assert_eq!(back, values);
        }
    }

    #[test]
    fn check_finite_names_the_voxel() {
        let dims = [4, 3, 2];
        let mut v = vec![0f32; 24];
        v[4 * 3 + 4 + 2] = f32::NAN; // (2,1,1)
        let err = check_finite("a.nrrd", dims, 0, &v, false)
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "a.nrrd: voxel (2,1,1) is NaN (if NaN means \"no data\" here, import with --nan empty)"
        );
        assert!(check_finite("a.nrrd", dims, 0, &v, true).is_ok());
        let err = check_finite("a.nrrd", dims, 12, &[0.0, f32::NEG_INFINITY], true).unwrap_err();
        assert_eq!(err.to_string(), "a.nrrd: voxel (1,0,1) is -infinity");
    }

    #[test]
    fn absurd_sizes_are_rejected_not_overflowed() {
        let info = VolumeInfo {
            dims: [1 << 24, 1 << 24, 1 << 24],
            spacing: [1.0; 3],
            voxel_type: VoxelType::F32,
        };
        let err = check_info("big.nrrd", &info, "sizes", "spacings").unwrap_err();
        assert_eq!(
            err.to_string(),
            "big.nrrd: sizes: the volume is too large to address"
        );
        // A side past the cap, as a crafted header gives (2^63 + 1 once
        // wrapped the octree layout's loop).
        let info = VolumeInfo {
            dims: [(1 << 63) + 1, 1, 1],
            ..info
        };
        let err = check_info("big.nrrd", &info, "sizes", "spacings").unwrap_err();
        assert!(
            err.to_string()
                .starts_with("big.nrrd: sizes: axis 0 has 9223372036854775809 voxels; a volume may have at most 16777216"),
            "{err}"
        );
    }

    #[test]
    fn open_dispatches_by_extension() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("thing.xyz");
        std::fs::File::create(&p)
            .unwrap()
            .write_all(&[0; 8])
            .unwrap();
        let err = open(&p, None).err().unwrap().to_string();
        assert!(
            err.contains("thing.xyz") && err.contains("unknown volume format"),
            "{err}"
        );

        let r = dir.path().join("thing.raw");
        std::fs::write(&r, [1u8, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        let err = open(&r, None).err().unwrap().to_string();
        assert!(err.contains("thing.raw") && err.contains("--dims"), "{err}");

        // Raw parameters override the extension.
        let params = RawParams {
            dims: [2, 2, 2],
            voxel_type: VoxelType::U8,
            spacing: [1.0, 1.0, 1.0],
            byte_offset: 0,
            big_endian: false,
        };
        let mut src = open(&p, Some(params)).unwrap();
        let mut out = [0f32; 8];
        src.read_slices(&mut out).unwrap();
        assert_eq!(out, [0.0; 8]);
    }
}
