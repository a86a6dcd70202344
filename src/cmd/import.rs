//! `parallax import`: a volume into the out-of-core octree database.

use super::args;
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use parallax_backend::data::{self, RawParams};
use parallax_backend::store::codec::Codec;
use parallax_backend::store::{self, BrickEncoding, ImportOptions};
use parallax_backend::volume::{VolumeSource, VoxelType};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Import a volume into the out-of-core octree database (.pxo).
#[derive(clap::Args)]
pub struct Args {
    /// .nrrd | .nhdr | .nii | .nii.gz | .raw (with --dims/--type/--spacing)
    /// | .tif/.tiff (multi-page) | a folder of DICOM slices or of TIFFs |
    /// an OME-Zarr image or Zarr array (v2 or v3)
    input: PathBuf,
    #[arg(short, long)]
    output: PathBuf,
    /// Brick side in voxels (overlap excluded).
    #[arg(long, default_value_t = 32)]
    brick: usize,
    /// Drop bricks whose values are all below this value.
    #[arg(long, allow_hyphen_values = true)]
    empty_below: Option<f32>,
    /// u8 | u16 (quantised against each brick's range) | none (full precision)
    #[arg(long, default_value = "u8", value_parser = args::encoding)]
    quantize: BrickEncoding,
    /// Brick compression: lz4 | zstd | zstdN (level 1–19), each optionally
    /// +delta (a delta pre-filter) or +auto (per brick, the smaller of
    /// the two).
    #[arg(long, default_value = "zstd1+auto", value_parser = args::codec)]
    codec: Codec,
    /// Memory budget of the import (MiB).
    #[arg(long, default_value_t = 2048)]
    memory_mb: usize,
    /// Halve all three axes at every level even over thick slices (by
    /// default the levels above anisotropic voxels halve the finer axes
    /// first, until the voxels are near-cubic)
    #[arg(long)]
    isotropic_levels: bool,
    /// A label volume (segmentation): whole labels, stored exactly, each
    /// coarser voxel one of the labels it covers (never an average); the
    /// database lists its labels for a layer's colour table
    #[arg(long)]
    labels: bool,
    /// Average every coarser level from the finer one, even where the file
    /// holds its own (an OME-Zarr pyramid halving as the octree does,
    /// taken by default)
    #[arg(long)]
    recompute_levels: bool,
    /// A label volume made from the input: label k where the value is at
    /// or above the k-th of these ascending thresholds (0 below the first);
    /// implies --labels
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    labels_from_thresholds: Option<Vec<f32>>,
    /// Raw input: X,Y,Z
    #[arg(long, value_parser = args::list::<usize, 3>)]
    dims: Option<[usize; 3]>,
    /// Raw input: u8 | i8 | u16 | i16 | u32 | i32 | f32 | f64
    #[arg(long = "type", value_parser = args::voxel_type)]
    voxel_type: Option<VoxelType>,
    /// Raw, TIFF or Zarr input: sx,sy,sz (raw default 1,1,1; TIFF default
    /// from ImageJ metadata, else 1,1,1; OME-Zarr from its scale)
    #[arg(long, value_parser = args::list::<f64, 3>)]
    spacing: Option<[f64; 3]>,
    /// DICOM folder with several series: the SeriesInstanceUID to import
    /// (or its number in the listing)
    #[arg(long)]
    series: Option<String>,
    /// OME-Zarr: the resolution level to import (0, the finest, by default)
    #[arg(long)]
    level: Option<usize>,
    /// OME-Zarr: the channel to import (0 by default)
    #[arg(long)]
    channel: Option<usize>,
    /// OME-Zarr or 4-D NIfTI: the time point to import (0 by default)
    #[arg(long)]
    time: Option<usize>,
    /// OME-Zarr or 4-D NIfTI: import every time point, each into
    /// OUTPUT/tNNNN.pxo (OUTPUT a folder): a scene's `series`
    #[arg(long, conflicts_with = "time")]
    all_times: bool,
    /// NaN in float input: refuse (an error naming the voxel) or empty
    /// ("no data": never shown, never blended into its neighbours)
    #[arg(long, value_enum, default_value_t = NanPolicy::Refuse)]
    nan: NanPolicy,
    /// Raw input: bytes to skip before the data
    #[arg(long, default_value_t = 0)]
    byte_offset: u64,
    /// Raw input: big-endian samples
    #[arg(long)]
    big_endian: bool,
}

/// What NaN in float input means.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum NanPolicy {
    /// An error naming the voxel.
    Refuse,
    /// No data: never shown, never blended into its neighbours.
    Empty,
}

pub fn run(a: Args) -> Result<()> {
    if !a.all_times {
        return import_one(&a, a.time, &a.output);
    }
    let times = open(&a, None)?.time_points();
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("{}: cannot create the series' folder", a.output.display()))?;
    let mut names = Vec::with_capacity(times);
    for t in 0..times {
        let name = format!("t{t:04}.pxo");
        eprintln!("time point {t} of {times}:");
        import_one(&a, Some(t), &a.output.join(&name))?;
        names.push(format!("\"{}/{name}\"", a.output.display()));
    }
    println!(
        "{times} time points in {}; a scene draws them with\nseries = [{}]",
        a.output.display(),
        names.join(", ")
    );
    Ok(())
}

/// The input, time point `time` chosen.
fn open(a: &Args, time: Option<usize>) -> Result<Box<dyn VolumeSource + Send>> {
    let raw = match (a.dims, a.voxel_type) {
        (Some(d), Some(t)) => Some(RawParams {
            dims: d,
            voxel_type: t,
            spacing: a.spacing.unwrap_or([1.0; 3]),
            byte_offset: a.byte_offset,
            big_endian: a.big_endian,
        }),
        (None, None) => None,
        _ => bail!("raw input needs both --dims and --type"),
    };
    data::open_with(
        &a.input,
        &data::InputOptions {
            raw,
            series: a.series.clone(),
            spacing: a.spacing,
            nan_empty: a.nan == NanPolicy::Empty,
            zarr: data::zarr::ZarrSelect {
                level: a.level,
                channel: a.channel,
                time,
            },
        },
    )
}

/// Imports time point `time` of the input into `output`.
fn import_one(a: &Args, time: Option<usize>, output: &Path) -> Result<()> {
    let mut src = open(a, time)?;
    if let Some(t) = a.labels_from_thresholds.clone() {
        src = Box::new(data::Thresholded::new(src, t)?);
    }
    let described = src.describe();
    if let Some(d) = &described {
        eprintln!("note: {d}");
    }
    let times = src.time_points();
    if times > 1 && !a.all_times && a.input.to_string_lossy().to_lowercase().contains(".nii") {
        eprintln!(
            "note: time point {} of {times} (--time; --all-times imports every one)",
            time.unwrap_or(0)
        );
    }
    let opts = ImportOptions {
        brick: a.brick,
        encoding: a.quantize,
        codec: a.codec,
        empty_below: a.empty_below,
        memory_mb: a.memory_mb,
        progress: std::io::stderr().is_terminal(),
        isotropic_levels: a.isotropic_levels,
        labels: a.labels || a.labels_from_thresholds.is_some(),
        pyramid: !a.recompute_levels,
    };
    let name = a.input.display().to_string();
    let source = match &described {
        Some(d) => format!("{name} ({d})"),
        None => name.clone(),
    };
    let r = store::import(src.as_mut(), output, &source, &opts)?;
    if let Some(note) = src.conversion_note() {
        eprintln!("note: {note}");
    }
    if r.no_data_voxels > 0 {
        eprintln!(
            "note: {} voxels are NaN: no data (never shown, never blended into their neighbours)",
            r.no_data_voxels
        );
    }
    println!(
        "imported {} → {}: {} nodes ({} stored, {} empty), {:.1} MB → {:.1} MB in {:.2} s ({:.0} MB/s of source)",
        name,
        output.display(),
        r.nodes,
        r.stored,
        r.empty,
        r.source_bytes as f64 / 1e6,
        r.file_bytes as f64 / 1e6,
        r.seconds,
        r.source_bytes as f64 / 1e6 / r.seconds.max(1e-9)
    );
    for p in &r.pyramid {
        println!(
            "level {} from the file's resolution level {}: it differs from the average of the finer level by {:.4} RMS, at most {:.4} ({} voxels)",
            p.level, p.file_level, p.rms, p.max, p.voxels
        );
    }
    for u in &r.pyramid_unused {
        eprintln!("note: {u}");
    }
    if let Some(l) = &r.summary.labels {
        println!("labels: {}", store::label_list(l));
    }
    if let Some(kb) = peak_rss_kib() {
        println!("peak resident memory: {:.1} MiB", kb as f64 / 1024.0);
    }
    Ok(())
}

/// Peak resident set size of this process (Linux: VmHWM), in KiB.
fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}
