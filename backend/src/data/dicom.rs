//! DICOM series (a folder of single-frame slices) through dicom-rs.
//!
//! `parallax import DIR/` reads every DICOM file of the folder (files without
//! the `DICM` preamble, and `DICOMDIR`, are skipped), groups them by
//! SeriesInstanceUID and, for the chosen series:
//!
//! * orders the slices by their position along the slice normal
//!   n = row × column of ImageOrientationPatient (0020,0037), the position
//!   being ImagePositionPatient (0020,0032) · n, whatever the file names;
//! * takes the in-plane spacing from PixelSpacing (0028,0030) and the slice
//!   spacing from the positions (not SliceThickness, which may overlap or
//!   leave gaps), refusing uneven spacing, missing slices, duplicated
//!   positions and gantry tilt, each naming the files and the tag;
//! * applies RescaleSlope / RescaleIntercept (0028,1053 / 0028,1052) slice by
//!   slice, so CT values are Hounsfield units;
//! * streams: one slice is decoded at a time.
//!
//! Volume space: x along the rows' direction (the first ImageOrientationPatient
//! vector), y along the columns', z along n, a right-handed frame. The patient
//! orientation (LPS direction cosines and the first slice's position) is
//! recorded in the description that import stores in the `.pxo`.
//!
//! Pixel data in the transfer syntaxes dicom-rs decodes in pure Rust
//! (uncompressed, deflate, RLE lossless, JPEG baseline/extended/lossless)
//! imports; others are refused naming the syntax.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, OpenFileOptions};
use dicom_pixeldata::{ConvertOptions, ModalityLutOption, PixelDecoder};

use super::{check_finite, check_info};
use crate::volume::{VolumeInfo, VolumeSource, VoxelType};

/// Relative tolerance on slice spacing: positions are written as decimal
/// strings of limited precision.
const SPACING_TOLERANCE: f64 = 0.01;

/// What one slice file says, read up to (not including) its pixel data.
#[derive(Clone, Debug)]
struct SliceMeta {
    path: PathBuf,
    series: String,
    description: String,
    rows: usize,
    columns: usize,
    pixel_spacing: [f64; 2],
    orientation: [f64; 6],
    position: [f64; 3],
    frames: u32,
    samples_per_pixel: u16,
    bits_allocated: u16,
    signed: bool,
    slope: f64,
    intercept: f64,
    tilt: f64,
    transfer_syntax: String,
}

/// A series found in a folder: what `--series` chooses from.
#[derive(Clone, Debug, PartialEq)]
pub struct SeriesSummary {
    pub uid: String,
    pub description: String,
    pub slices: usize,
}

fn text(obj: &DefaultDicomObject, tag: dicom_object::Tag) -> Option<String> {
    obj.element_opt(tag)
        .ok()
        .flatten()
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim().trim_end_matches('\0').to_string())
}

fn floats(
    obj: &DefaultDicomObject,
    tag: dicom_object::Tag,
    name: &str,
    n: usize,
    label: &str,
) -> Result<Vec<f64>> {
    let e = obj
        .element_opt(tag)
        .ok()
        .flatten()
        .with_context(|| format!("{label}: {name} {tag} is missing"))?;
    let v = e
        .to_multi_float64()
        .with_context(|| format!("{label}: {name} {tag}: not numbers"))?;
    ensure!(
        v.len() == n,
        "{label}: {name} {tag}: {} values, expected {n}",
        v.len()
    );
    ensure!(
        v.iter().all(|x| x.is_finite()),
        "{label}: {name} {tag}: {v:?} is not finite"
    );
    Ok(v)
}

fn int_or(
    obj: &DefaultDicomObject,
    tag: dicom_object::Tag,
    name: &str,
    default: Option<i64>,
    label: &str,
) -> Result<i64> {
    match obj.element_opt(tag).ok().flatten() {
        Some(e) => e
            .to_int::<i64>()
            .with_context(|| format!("{label}: {name} {tag}: not an integer")),
        None => default.with_context(|| format!("{label}: {name} {tag} is missing")),
    }
}

fn float_or(
    obj: &DefaultDicomObject,
    tag: dicom_object::Tag,
    name: &str,
    default: f64,
    label: &str,
) -> Result<f64> {
    match obj.element_opt(tag).ok().flatten() {
        Some(e) => {
            let v = e
                .to_float64()
                .with_context(|| format!("{label}: {name} {tag}: not a number"))?;
            ensure!(v.is_finite(), "{label}: {name} {tag}: {v} is not finite");
            Ok(v)
        }
        None => Ok(default),
    }
}

/// Whether a file starts with the DICOM preamble and magic.
fn is_dicom(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && &head[128..132] == b"DICM"
}

/// The largest single allocation dicom-rs may make for one file: 256 MiB
/// (a 65535² slice of 16 bits is 8 GiB, a real one a few MiB), or 16× the
/// file for a compressed one. A crafted length above it is an error, not
/// gigabytes touched.
fn decode_cap(path: &Path) -> usize {
    let size = std::fs::metadata(path).map_or(0, |m| m.len() as usize);
    (256 << 20usize).max(size.saturating_mul(16))
}

/// Refuses a file whose element lengths run past its end before dicom-rs
/// allocates them ([`super::dicom_lengths`]); files over 512 MiB (no slice
/// is) are left to dicom-rs.
fn check_lengths(path: &Path, label: &str) -> Result<()> {
    let size = std::fs::metadata(path)
        .with_context(|| format!("{label}: cannot read"))?
        .len();
    if size <= 512 << 20 {
        let bytes = std::fs::read(path).with_context(|| format!("{label}: cannot read"))?;
        super::dicom_lengths::check(label, &bytes)?;
    }
    Ok(())
}

fn read_meta(path: &Path) -> Result<SliceMeta> {
    let label = path.display().to_string();
    check_lengths(path, &label)?;
    let obj = super::contain::contained(&label, "the DICOM parser", decode_cap(path), || {
        OpenFileOptions::new()
            .read_until(tags::PIXEL_DATA)
            .open_file(path)
            .with_context(|| format!("{label}: not a readable DICOM file"))
    })?;
    let spacing = floats(&obj, tags::PIXEL_SPACING, "PixelSpacing", 2, &label)?;
    let orientation = floats(
        &obj,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
        6,
        &label,
    )?;
    let position = floats(
        &obj,
        tags::IMAGE_POSITION_PATIENT,
        "ImagePositionPatient",
        3,
        &label,
    )?;
    let rows = int_or(&obj, tags::ROWS, "Rows", None, &label)?;
    let columns = int_or(&obj, tags::COLUMNS, "Columns", None, &label)?;
    ensure!(
        (1..=65535).contains(&rows) && (1..=65535).contains(&columns),
        "{label}: Rows × Columns (0028,0010)/(0028,0011) is {rows} × {columns}"
    );
    let slope = float_or(&obj, tags::RESCALE_SLOPE, "RescaleSlope", 1.0, &label)?;
    ensure!(
        slope != 0.0,
        "{label}: RescaleSlope (0028,1053) is 0: every value would be the intercept"
    );
    Ok(SliceMeta {
        path: path.to_path_buf(),
        series: text(&obj, tags::SERIES_INSTANCE_UID).unwrap_or_default(),
        description: text(&obj, tags::SERIES_DESCRIPTION).unwrap_or_default(),
        rows: rows as usize,
        columns: columns as usize,
        pixel_spacing: [spacing[0], spacing[1]],
        orientation: orientation.try_into().unwrap(),
        position: position.try_into().unwrap(),
        frames: int_or(
            &obj,
            tags::NUMBER_OF_FRAMES,
            "NumberOfFrames",
            Some(1),
            &label,
        )? as u32,
        samples_per_pixel: int_or(
            &obj,
            tags::SAMPLES_PER_PIXEL,
            "SamplesPerPixel",
            Some(1),
            &label,
        )? as u16,
        bits_allocated: int_or(&obj, tags::BITS_ALLOCATED, "BitsAllocated", None, &label)? as u16,
        signed: int_or(
            &obj,
            tags::PIXEL_REPRESENTATION,
            "PixelRepresentation",
            Some(0),
            &label,
        )? == 1,
        slope,
        intercept: float_or(
            &obj,
            tags::RESCALE_INTERCEPT,
            "RescaleIntercept",
            0.0,
            &label,
        )?,
        tilt: float_or(
            &obj,
            tags::GANTRY_DETECTOR_TILT,
            "GantryDetectorTilt",
            0.0,
            &label,
        )?,
        transfer_syntax: obj
            .meta()
            .transfer_syntax()
            .trim_end_matches('\0')
            .to_string(),
    })
}

/// Reads the metadata of every DICOM file in `dir`, grouped by series.
fn scan(dir: &Path) -> Result<BTreeMap<String, Vec<SliceMeta>>> {
    let label = dir.display();
    let mut series: BTreeMap<String, Vec<SliceMeta>> = BTreeMap::new();
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{label}: cannot list the folder"))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    entries.sort();
    let mut skipped = 0;
    for p in entries {
        let name = p.file_name().unwrap_or_default().to_string_lossy();
        if name.eq_ignore_ascii_case("DICOMDIR") || !is_dicom(&p) {
            skipped += 1;
            continue;
        }
        let m = read_meta(&p)?;
        series.entry(m.series.clone()).or_default().push(m);
    }
    ensure!(
        !series.is_empty(),
        "{label}: no DICOM files in the folder ({skipped} other files)"
    );
    Ok(series)
}

/// The series of a folder of DICOM files: UID, description, slice count.
pub fn list_series(dir: &Path) -> Result<Vec<SeriesSummary>> {
    Ok(scan(dir)?
        .into_iter()
        .map(|(uid, s)| SeriesSummary {
            description: s[0].description.clone(),
            slices: s.len(),
            uid,
        })
        .collect())
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned()
}

/// A DICOM series read slice by slice.
pub struct DicomSource {
    label: String,
    info: VolumeInfo,
    slices: Vec<SliceMeta>,
    next: usize,
    description: String,
    /// Volume space → LPS mm, from the first slice's position and the
    /// orientation (`VolumeSource::world`).
    world: Option<[[f64; 4]; 3]>,
}

impl DicomSource {
    /// What import records of the series: UID, description and the patient
    /// orientation of the volume's axes (LPS).
    pub fn description(&self) -> &str {
        &self.description
    }
}

/// Opens the series of `dir` (the only one, or the one `series` names by
/// UID or by its number in the listing, from 1).
pub fn open_dicom(dir: &Path, series: Option<&str>) -> Result<DicomSource> {
    let label = dir.display().to_string();
    let all = scan(dir)?;
    let (uid, mut slices) = choose_series(&label, &all, series)?;
    let first = slices[0].clone();
    check_slices(&label, &slices)?;
    let f0 = file_name(&first.path);
    let row: [f64; 3] = first.orientation[0..3].try_into().unwrap();
    let col: [f64; 3] = first.orientation[3..6].try_into().unwrap();
    let normal = cross(row, col);
    let nn = dot(normal, normal).sqrt();
    ensure!(
        nn > 0.5 && (dot(row, row).sqrt() - 1.0).abs() < 1e-3 && (dot(col, col).sqrt() - 1.0).abs() < 1e-3,
        "{label}: {f0}: ImageOrientationPatient (0020,0037) {:?} is not two orthogonal unit vectors",
        first.orientation
    );
    let normal = normal.map(|c| c / nn);
    slices.sort_by(|a, b| dot(a.position, normal).total_cmp(&dot(b.position, normal)));
    let z: Vec<f64> = slices.iter().map(|s| dot(s.position, normal)).collect();
    let spacing_z = slice_spacing(&label, &slices, &z, normal)?;
    // DICOM PixelSpacing is (row spacing, column spacing): between rows (y)
    // first, then between columns (x).
    let info = VolumeInfo {
        dims: [first.columns, first.rows, slices.len()],
        spacing: [first.pixel_spacing[1], first.pixel_spacing[0], spacing_z],
        voxel_type: voxel_type(&slices),
    };
    check_info(&label, &info, "Rows/Columns", "PixelSpacing")?;
    let p0 = slices[0].position;
    let description = format!(
        "DICOM series {uid} \"{}\" ({} slices); patient (LPS) directions: x {:?}, y {:?}, z {:?}; first voxel at {:?} mm",
        first.description,
        slices.len(),
        row.map(round6),
        col.map(round6),
        normal.map(round6),
        p0.map(round6)
    );
    // Voxel (i, j, k)'s centre: p0 + i·Δx·row + j·Δy·column + k·Δz·n.
    let steps = [row, col, normal]
        .iter()
        .zip(info.spacing)
        .map(|(d, s)| d.map(|c| c * s))
        .collect::<Vec<_>>();
    let world = super::world_from(p0, [steps[0], steps[1], steps[2]], info.spacing);
    let src = DicomSource {
        label,
        info,
        slices,
        next: 0,
        description,
        world,
    };
    // Decode the first slice now: an unsupported transfer syntax is reported
    // before anything is written.
    let mut probe = vec![0f32; src.info.dims[0] * src.info.dims[1]];
    src.decode_slice(0, &mut probe)?;
    Ok(src)
}

/// The series of `all` that `series` names (by UID or by its number in the
/// listing, from 1), or the only one.
fn choose_series(
    label: &str,
    all: &BTreeMap<String, Vec<SliceMeta>>,
    series: Option<&str>,
) -> Result<(String, Vec<SliceMeta>)> {
    let listing = || {
        all.iter()
            .enumerate()
            .map(|(i, (uid, s))| {
                format!(
                    "  {}: {uid}  \"{}\"  {} slices",
                    i + 1,
                    s[0].description,
                    s.len()
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let (uid, slices) = match series {
        None if all.len() == 1 => all.iter().next().unwrap(),
        None => bail!(
            "{label}: the folder holds {} series; choose one with --series UID (or its number):\n{}",
            all.len(),
            listing()
        ),
        Some(want) => {
            let by_number = want
                .parse::<usize>()
                .ok()
                .filter(|&n| n >= 1 && n <= all.len())
                .and_then(|n| all.iter().nth(n - 1));
            by_number
                .or_else(|| all.get_key_value(want))
                .with_context(|| {
                    format!("{label}: --series {want}: no such series; the folder holds:\n{}", listing())
                })?
        }
    };
    Ok((uid.clone(), slices.clone()))
}

/// Every slice of a series is a single-frame greyscale image of the first
/// one's size, pixel spacing and orientation, from an untilted gantry.
fn check_slices(label: &str, slices: &[SliceMeta]) -> Result<()> {
    let first = &slices[0];
    let f0 = file_name(&first.path);
    ensure!(
        first.frames == 1,
        "{label}: {f0}: NumberOfFrames (0028,0008) is {}: multi-frame DICOM is not supported; \
         export the series as single-frame slices",
        first.frames
    );
    ensure!(
        first.samples_per_pixel == 1,
        "{label}: {f0}: SamplesPerPixel (0028,0002) is {}: only greyscale volumes import",
        first.samples_per_pixel
    );
    for s in slices {
        let f = file_name(&s.path);
        ensure!(
            s.rows == first.rows && s.columns == first.columns,
            "{label}: {f}: Rows × Columns (0028,0010)/(0028,0011) is {} × {}, but {f0} has {} × {}",
            s.rows,
            s.columns,
            first.rows,
            first.columns
        );
        ensure!(
            s.pixel_spacing
                .iter()
                .zip(first.pixel_spacing)
                .all(|(a, b)| (a - b).abs() <= 1e-4 * b.abs()),
            "{label}: {f}: PixelSpacing (0028,0030) is {:?}, but {f0} has {:?}",
            s.pixel_spacing,
            first.pixel_spacing
        );
        ensure!(
            s.orientation
                .iter()
                .zip(first.orientation)
                .all(|(a, b)| (a - b).abs() <= 1e-4),
            "{label}: {f}: ImageOrientationPatient (0020,0037) differs from {f0}'s"
        );
        ensure!(
            s.frames == 1 && s.samples_per_pixel == 1,
            "{label}: {f}: NumberOfFrames / SamplesPerPixel differ from {f0}'s"
        );
        ensure!(
            s.tilt.abs() <= 1e-3,
            "{label}: {f}: GantryDetectorTilt (0018,1120) is {}°: tilted-gantry series are \
             not supported (their slices are sheared, not stacked); resample them first",
            s.tilt
        );
    }
    Ok(())
}

/// The spacing along the slice normal of slices sorted by their position
/// `z` along it: even gaps (a missing, duplicate or uneven slice is named),
/// stacked along the normal; one slice takes its finer pixel spacing.
fn slice_spacing(label: &str, slices: &[SliceMeta], z: &[f64], normal: [f64; 3]) -> Result<f64> {
    if slices.len() == 1 {
        let first = &slices[0];
        return Ok(first.pixel_spacing[0].min(first.pixel_spacing[1]));
    }
    let gaps: Vec<f64> = z.windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted = gaps.clone();
    sorted.sort_by(f64::total_cmp);
    let typical = sorted[sorted.len() / 2];
    for (i, &g) in gaps.iter().enumerate() {
        let (a, b) = (file_name(&slices[i].path), file_name(&slices[i + 1].path));
        ensure!(
            g > 1e-6,
            "{label}: {a} and {b} have the same ImagePositionPatient (0020,0032) along the slice normal (duplicate slice?)"
        );
        if (g - typical).abs() > SPACING_TOLERANCE * typical {
            let ratio = g / typical;
            if (ratio - ratio.round()).abs() < 0.05 && ratio.round() >= 2.0 {
                bail!(
                    "{label}: missing slice: between {a} and {b} the ImagePositionPatient (0020,0032) \
                     gap is {g:.4} mm, {:.0}× the series' spacing of {typical:.4} mm",
                    ratio.round()
                );
            }
            bail!(
                "{label}: uneven slice spacing: ImagePositionPatient (0020,0032) of {a} and {b} are \
                 {g:.4} mm apart, the series' spacing is {typical:.4} mm"
            );
        }
    }
    // Slices must stack along the normal: an in-plane drift between
    // neighbours is a sheared (tilted) acquisition.
    for w in slices.windows(2) {
        let d = [0, 1, 2].map(|i| w[1].position[i] - w[0].position[i]);
        let along = dot(d, normal);
        let off = (dot(d, d) - along * along).max(0.0).sqrt();
        ensure!(
            off <= 0.01 * along.abs() + 1e-4,
            "{label}: {} and {}: ImagePositionPatient (0020,0032) moves {off:.4} mm within the slice plane \
             between slices (a gantry tilt or sheared series), which is not supported",
            file_name(&w[0].path),
            file_name(&w[1].path)
        );
    }
    Ok((z[z.len() - 1] - z[0]) / (z.len() - 1) as f64)
}

fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The voxel type the rescaled values fit: i16 for the usual CT, u8/u16 when
/// no rescale applies, f32 otherwise.
fn voxel_type(slices: &[SliceMeta]) -> VoxelType {
    let s = &slices[0];
    let identity = slices.iter().all(|m| m.slope == 1.0 && m.intercept == 0.0);
    let integral = slices
        .iter()
        .all(|m| m.slope.fract() == 0.0 && m.intercept.fract() == 0.0);
    match (s.bits_allocated, s.signed) {
        (8, false) if identity => VoxelType::U8,
        (8, true) if identity => VoxelType::I8,
        (16, false) if identity => VoxelType::U16,
        (16, true) if identity => VoxelType::I16,
        (16, _)
            if integral
                && slices
                    .iter()
                    .all(|m| m.slope == 1.0 && m.intercept.abs() <= 32768.0) =>
        {
            // stored + intercept: i16 holds the usual CT (stored 0…4095,
            // intercept −1024); wider results go to f32.
            if s.signed {
                VoxelType::F32
            } else {
                VoxelType::I16
            }
        }
        _ => VoxelType::F32,
    }
}

impl DicomSource {
    fn decode_slice(&self, k: usize, out: &mut [f32]) -> Result<()> {
        let m = &self.slices[k];
        // Its lengths were checked when the series was opened (read_meta);
        // the decoder's allocations are capped besides.
        let label = format!("{}: {}", self.label, file_name(&m.path));
        let raw: Vec<f64> =
            super::contain::contained(&label, "the DICOM decoder", decode_cap(&m.path), || {
                let obj = dicom_object::open_file(&m.path)
                    .with_context(|| format!("{label}: cannot read"))?;
                let pixels = obj.decode_pixel_data().with_context(|| {
                    format!(
                    "{label}: cannot decode the pixel data (TransferSyntaxUID (0002,0010) {}{})",
                    m.transfer_syntax,
                    syntax_name(&m.transfer_syntax)
                )
                })?;
                let opts = ConvertOptions::new().with_modality_lut(ModalityLutOption::None);
                pixels
                    .to_vec_frame_with_options(0, &opts)
                    .with_context(|| format!("{label}: converting the pixel data"))
            })?;
        ensure!(
            raw.len() == out.len(),
            "{label}: the pixel data holds {} values, Rows × Columns is {}",
            raw.len(),
            out.len()
        );
        for (o, r) in out.iter_mut().zip(raw) {
            *o = (m.slope * r + m.intercept) as f32;
        }
        Ok(())
    }
}

/// A readable name for the transfer syntaxes people meet.
fn syntax_name(uid: &str) -> &'static str {
    match uid {
        "1.2.840.10008.1.2" => " (implicit VR little endian)",
        "1.2.840.10008.1.2.1" => " (explicit VR little endian)",
        "1.2.840.10008.1.2.2" => " (explicit VR big endian)",
        "1.2.840.10008.1.2.5" => " (RLE lossless)",
        "1.2.840.10008.1.2.4.50" => " (JPEG baseline)",
        "1.2.840.10008.1.2.4.70" => " (JPEG lossless)",
        "1.2.840.10008.1.2.4.80" | "1.2.840.10008.1.2.4.81" => {
            " (JPEG-LS: not decoded by this build; convert the series to an uncompressed syntax)"
        }
        "1.2.840.10008.1.2.4.90" | "1.2.840.10008.1.2.4.91" => {
            " (JPEG 2000: not decoded by this build; convert the series to an uncompressed syntax)"
        }
        _ => "",
    }
}

impl VolumeSource for DicomSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, out: &mut [f32]) -> Result<()> {
        let mut next = self.next;
        let res = super::slice_by_slice(&self.label, &self.info, &mut next, out, |k, chunk| {
            self.decode_slice(k, chunk)?;
            // Rescaling cannot make NaN from integers, but it can overflow.
            check_finite(
                &self.label,
                self.info.dims,
                (k * chunk.len()) as u64,
                chunk,
                false,
            )
        });
        self.next = next;
        res
    }

    fn describe(&self) -> Option<String> {
        Some(self.description.clone())
    }

    fn world(&self) -> Option<[[f64; 4]; 3]> {
        self.world
    }
}
