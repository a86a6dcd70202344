//! `parallax render`: a scene's display, frame by frame, to files.

use super::args;
use crate::launch;
use anyhow::Result;
use std::path::PathBuf;

/// Render a scene's display: PNG per projector (and .npy with --float),
/// stats.jsonl per frame.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    target: args::SceneDisplay,
    /// Frames to render (default: the script's length, or until the cut
    /// has converged).
    #[arg(long, default_value_t = 0)]
    frames: u64,
    /// Interaction script (keyframes of placement, observer, η, transfer function).
    #[arg(long)]
    script: Option<PathBuf>,
    /// Output folder: DIR/frame_NNNNN/<projector>.png, DIR/stats.jsonl
    /// (default: out/<scene name>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write float32 .npy images (linear, premultiplied).
    #[arg(long)]
    float: bool,
    /// Wait for every posted brick read before each frame (reproducible
    /// frames; otherwise the loader never blocks).
    #[arg(long)]
    sync: bool,
    /// Back-end threads in the embedded (single-process) mode (default:
    /// the highest rank the display's projector files name, or 1).
    #[arg(long)]
    backends: Option<usize>,
    /// Show every frame on the display's outputs (the display file's
    /// `[present]`: a borderless window per output, each projector at its
    /// viewport), all back ends presenting together (swap lock).
    #[arg(long)]
    present: bool,
    /// With --present: keep the last frame on the outputs this many
    /// seconds after the run.
    #[arg(long, default_value_t = 0.0, requires = "present", value_parser = args::hold)]
    hold: f64,
    /// Seconds to wait for a back end's frame before naming it and
    /// ending the run (0: wait forever).
    #[arg(long, default_value_t = parallax_common::protocol::DEFAULT_WATCHDOG.as_secs_f64())]
    watchdog: f64,
}

pub fn run(a: Args) -> Result<()> {
    let watchdog = args::watchdog(a.watchdog)?;
    let out = a.out.unwrap_or_else(|| {
        let stem = a.target.scene.file_stem().unwrap_or_default();
        PathBuf::from("out").join(stem)
    });
    let opts = parallax_frontend::RunOptions {
        scene: a.target.scene,
        display: a.target.display,
        frames: a.frames,
        out: Some(out.clone()),
        float: a.float,
        sync_io: a.sync,
        script: a.script,
        verbose: true,
        watchdog,
        present: a.present.then_some(a.hold),
    };
    let role = launch::session(&opts.scene, opts.display.as_ref(), a.backends, |t| {
        parallax_frontend::run(&opts, t).map(|_| ())
    })?;
    if role == launch::Role::Coordinator {
        println!("images and stats.jsonl in {}", out.display());
    }
    Ok(())
}
