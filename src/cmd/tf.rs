//! `parallax tf import`: ParaView and 3D Slicer presets as Parallax TOML.

use super::args;
use anyhow::{Context, Result};
use clap::Subcommand;
use parallax_backend::data::presets;
use std::path::PathBuf;

/// Transfer functions: import ParaView and 3D Slicer presets.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    action: Action,
}

#[derive(Subcommand)]
enum Action {
    /// Convert a ParaView colour-map JSON (with or without opacity points),
    /// a 3D Slicer presets.xml, .vp or .vp.json into Parallax's TOML.
    Import(ImportArgs),
}

#[derive(clap::Args)]
struct ImportArgs {
    input: PathBuf,
    /// The preset in a file of several (exact, unique case-insensitive
    /// match, or #N); --list shows them.
    #[arg(long)]
    name: Option<String>,
    /// List the presets in the file and stop.
    #[arg(long)]
    list: bool,
    /// lo,hi: stretch the preset over this data range (as ParaView
    /// applies a preset; needed for normalised colour maps).
    #[arg(long, allow_hyphen_values = true, value_parser = args::list::<f64, 2>)]
    range: Option<[f64; 2]>,
    /// VTK's scalar opacity unit distance, in data length units
    /// (default: the file's, else 1).
    #[arg(long)]
    unit: Option<f64>,
    /// Opacity of a preset that has none: ramp | ramp:LOW,HIGH | const:A |
    /// reject.
    #[arg(long, default_value = "ramp")]
    missing_opacity: presets::MissingOpacity,
    /// Keep colours as the preset's display values instead of decoding
    /// sRGB to linear.
    #[arg(long)]
    display_colours: bool,
    /// The TOML file to write (needed unless --list).
    #[arg(short, long, required_unless_present = "list")]
    output: Option<PathBuf>,
}

pub fn run(a: Args) -> Result<()> {
    let Action::Import(a) = a.action;
    if a.list {
        let text = std::fs::read_to_string(&a.input)
            .with_context(|| format!("{}: cannot read", a.input.display()))?;
        for n in presets::preset_names(&text, &a.input.display().to_string())? {
            println!("{n}");
        }
        return Ok(());
    }
    let opts = presets::ImportOptions {
        range: a
            .range
            .map(|[lo, hi]| {
                anyhow::ensure!(lo < hi, "--range {lo},{hi}: expected lo < hi");
                Ok((lo, hi))
            })
            .transpose()?,
        unit: a.unit,
        missing_opacity: a.missing_opacity,
        linearize: !a.display_colours,
        ..Default::default()
    };
    if let Some(u) = a.unit {
        anyhow::ensure!(
            u.is_finite() && u > 0.0,
            "--unit {u}: expected a positive length"
        );
    }
    let p = presets::import_preset_file(&a.input, a.name.as_deref(), &opts)?;
    for n in &p.notes {
        eprintln!("note: {n}");
    }
    let output = a
        .output
        .context("-o/--output: where to write the transfer function")?;
    parallax_common::atomic::write(&output, p.to_toml().as_bytes())?;
    println!(
        "wrote {} ({} \"{}\", {} points)",
        output.display(),
        p.format.description(),
        p.name,
        p.tf.points().len()
    );
    Ok(())
}
