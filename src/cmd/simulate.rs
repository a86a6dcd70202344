//! `parallax simulate`: what an eye sees on a light field display.

use super::args;
use anyhow::{bail, Result};
use parallax_backend::simulate as sim;
use std::path::PathBuf;

/// What an eye sees on a light field display, from the projector images
/// of one rendered frame (several --eye: a strip, left to right).
#[derive(clap::Args)]
pub struct Args {
    #[arg(long)]
    display: PathBuf,
    /// A frame folder written by `render` (DIR/frame_NNNNN).
    #[arg(long)]
    frames: PathBuf,
    /// Eye position x,y,z (m); repeat for a strip.
    #[arg(long, required = true, allow_hyphen_values = true)]
    eye: Vec<String>,
    /// Sweep: this many eyes evenly from the first --eye to the second.
    #[arg(long)]
    sweep: Option<usize>,
    /// Output resolution WxH (default: screen size / pixel size, capped).
    #[arg(long, value_parser = args::size::<u32>)]
    resolution: Option<[u32; 2]>,
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    let disp = parallax_common::config::Display::load(&a.display)?;
    let images = sim::load_frame(&disp, &a.frames)?;
    let mut eyes = a
        .eye
        .iter()
        .map(|e| sim::parse_eye(e))
        .collect::<Result<Vec<_>>>()?;
    if let Some(n) = a.sweep {
        if eyes.len() != 2 || n < 2 {
            bail!("--sweep N needs exactly two --eye positions (from, to) and N ≥ 2");
        }
        eyes = sim::sweep(eyes[0], eyes[1], n);
    }
    let res = match a.resolution {
        Some(r) => r,
        None => sim::default_resolution(&disp, sim::DEFAULT_MAX_SIDE),
    };
    let (w, h, px) = sim::strip(&disp, &images, &eyes, res)?;
    parallax_backend::output::write_png(&a.output, w, h, &px)?;
    println!(
        "wrote {} ({} eye{}, {w}×{h})",
        a.output.display(),
        eyes.len(),
        if eyes.len() > 1 { "s" } else { "" }
    );
    Ok(())
}
