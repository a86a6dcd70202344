//! Parallax front end: the coordinator (DESIGN.md "Process model"). It reads
//! the scene, sends the large state once, then every frame broadcasts a small
//! `FrameState`, waits for every back end's `FrameStats` (frames are
//! swap-locked) and writes them to `stats.jsonl`.

pub mod cluster;

use anyhow::{bail, Context, Result};
use parallax_common::config::{Display, Scene};
use parallax_common::protocol::{FrameState, FrameStats, ToBackend, Transport};
use parallax_common::tf::TransferFunction;
use std::io::Write;
use std::path::PathBuf;

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub scene: PathBuf,
    /// Overrides the scene's display.
    pub display: Option<PathBuf>,
    pub frames: u64,
    pub out: Option<PathBuf>,
    pub float: bool,
    pub sync_io: bool,
    /// Print a line per frame.
    pub verbose: bool,
}

/// What a run produced: every back end's figures for every frame.
#[derive(Debug, Default)]
pub struct RunSummary {
    pub frames: Vec<Vec<FrameStats>>,
}

/// The display a scene renders to.
pub fn load_display(scene: &Scene, over: Option<&PathBuf>) -> Result<Display> {
    let path = over
        .or(scene.display.as_ref())
        .context("no display: give --display or set `display` in the scene file")?;
    Display::load(path)
}

/// Runs a whole session over `transport` and tells the back ends to quit at
/// the end (also after an error, so no back end is left waiting).
pub fn run(opts: &RunOptions, transport: &mut dyn Transport) -> Result<RunSummary> {
    let result = run_frames(opts, transport);
    let _ = transport.broadcast(&ToBackend::Quit);
    result
}

fn run_frames(opts: &RunOptions, transport: &mut dyn Transport) -> Result<RunSummary> {
    let scene = Scene::load(&opts.scene)?;
    let display = load_display(&scene, opts.display.as_ref())?;
    display.assignment(transport.backends())?;
    let tf = TransferFunction::load(&scene.transfer_function)?;
    let mut stats_file = match &opts.out {
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create", dir.display()))?;
            let p = dir.join("stats.jsonl");
            Some(std::io::BufWriter::new(
                std::fs::File::create(&p)
                    .with_context(|| format!("{}: cannot create", p.display()))?,
            ))
        }
        None => None,
    };
    transport.broadcast(&ToBackend::Setup {
        scene: scene.clone(),
        display: display.clone(),
        out_dir: opts.out.clone(),
        float: opts.float,
        sync_io: opts.sync_io,
    })?;
    transport.broadcast(&ToBackend::TransferFunction { version: 1, tf })?;
    let mut summary = RunSummary::default();
    for frame in 0..opts.frames {
        let state = FrameState {
            frame,
            placement: scene.placement,
            observer: display.observer.position,
            eta: scene.render.eta,
            render: scene.render.clone(),
            tf_version: 1,
        };
        transport.broadcast(&ToBackend::Frame(state))?;
        let stats = transport.gather()?;
        if let Some(bad) = stats.iter().find(|s| s.error.is_some()) {
            bail!(
                "back end {} failed: {}",
                bad.rank,
                bad.error.as_deref().unwrap_or("")
            );
        }
        if let Some(f) = stats_file.as_mut() {
            for s in &stats {
                serde_json::to_writer(&mut *f, s)?;
                f.write_all(b"\n")?;
            }
        }
        if opts.verbose {
            println!("{}", frame_line(frame, &stats));
        }
        summary.frames.push(stats);
    }
    if let Some(mut f) = stats_file {
        f.flush()?;
    }
    Ok(summary)
}

/// One line per frame: the slowest back end and the bricks per back end.
pub fn frame_line(frame: u64, stats: &[FrameStats]) -> String {
    let slowest = stats
        .iter()
        .max_by(|a, b| a.total_ms.total_cmp(&b.total_ms))
        .expect("at least one back end");
    let bricks: Vec<u64> = stats.iter().map(|s| s.cut_leaves_with_data).collect();
    let avg = bricks.iter().sum::<u64>() as f64 / bricks.len() as f64;
    format!(
        "frame {frame:>5}: {:>8.1} ms (slowest rank {}), bricks per rank avg {avg:.0} max {}, uploaded {}, read {:.1} MB{}",
        slowest.total_ms,
        slowest.rank,
        bricks.iter().max().unwrap(),
        stats.iter().map(|s| s.uploaded).sum::<u64>(),
        stats.iter().map(|s| s.bytes_read).sum::<u64>() as f64 / 1e6,
        if stats.iter().all(|s| s.adequate) { ", converged" } else { "" }
    )
}
