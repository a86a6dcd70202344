//! `parallax synth`: a procedural volume as NRRD.

use super::args;
use anyhow::{bail, Result};
use parallax_backend::data::{self, synth::SynthKind};
use parallax_backend::volume::VoxelType;
use std::path::PathBuf;

/// Write a procedural volume as NRRD (streamed: any size fits in memory).
#[derive(clap::Args)]
pub struct Args {
    /// marschner-lobb | shells | shepp-logan | constant | plane | noise | stiff | ct
    /// (ct: a head in Hounsfield units with scanner noise; use --type i16)
    #[arg(value_parser = args::synth_kind)]
    kind: SynthKind,
    #[arg(long)]
    size: usize,
    /// u8 | i8 | u16 | i16 | u32 | i32 | f32 | f64
    #[arg(long = "type", default_value = "u8", value_parser = args::voxel_type)]
    voxel_type: VoxelType,
    /// vol.nrrd, or vol.ome.zarr (an OME-Zarr image: NGFF 0.5, Zarr v3,
    /// chunks of 64³, zstd)
    #[arg(short, long)]
    output: PathBuf,
    /// ct only: scan the same cube in this many thick slices (size × size ×
    /// slices voxels of 1 × 1 × size/slices), each averaging the anatomy
    /// across its thickness, as a clinical CT's 5 mm slices do.
    #[arg(long)]
    slices: Option<usize>,
}

pub fn run(a: Args) -> Result<()> {
    if a.size == 0 {
        bail!("--size 0: a volume needs at least one voxel");
    }
    if let Some(slices) = a.slices {
        if a.kind != SynthKind::Ct {
            bail!("--slices: only the ct phantom is scanned in thick slices");
        }
        let bar = progress(slices as u64, "synth");
        data::synth::write_thick_ct(a.size, slices, a.voxel_type, &a.output, |_| bar.inc(1))?;
        bar.finish_and_clear();
        println!(
            "wrote {} ({n} × {n} × {slices} {}, slices {:.3} thick)",
            a.output.display(),
            a.voxel_type.name(),
            a.size as f64 / slices as f64,
            n = a.size
        );
        return Ok(());
    }
    let bar = progress(a.size as u64, "synth");
    data::synth::write_synth(a.kind, a.size, a.voxel_type, &a.output, |_| bar.inc(1))?;
    bar.finish_and_clear();
    println!(
        "wrote {} ({}³ {})",
        a.output.display(),
        a.size,
        a.voxel_type.name()
    );
    Ok(())
}

fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(len),
        indicatif::ProgressDrawTarget::stderr(),
    );
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:40}} {{pos}}/{{len}} ({{eta}} left)"
        ))
        .unwrap(),
    );
    bar
}
