//! A back-end process (or thread): receives the front end's messages,
//! renders its projectors' views each frame, writes their images, replies
//! with the frame's figures (DESIGN.md "Process model").

use crate::output;
use crate::render::Renderer;
use anyhow::{Context, Result};
use parallax_common::camera::View;
use parallax_common::config::Display;
use parallax_common::protocol::{FrameState, FrameStats, Link, ToBackend};
use std::path::PathBuf;
use std::time::Instant;

struct Setup {
    display: Display,
    mine: Vec<usize>,
    out_dir: Option<PathBuf>,
    float: bool,
    renderer: Renderer,
}

/// Serves the front end until it says quit. After an error the back end
/// keeps answering every frame with that error (so the front end, which
/// waits for every back end each frame, learns which rank failed instead of
/// hanging) until it is told to quit; the error is then returned.
pub fn serve(link: &mut dyn Link, backends: usize) -> Result<()> {
    let mut setup: Option<Setup> = None;
    let mut failed: Option<anyhow::Error> = None;
    loop {
        let msg = link.receive()?;
        if let Some(e) = &failed {
            match msg {
                ToBackend::Quit => return Err(failed.take().unwrap()),
                ToBackend::Frame(_) => link.reply(&error_stats(link.rank(), e))?,
                _ => {}
            }
            continue;
        }
        let frame = matches!(msg, ToBackend::Frame(_));
        match handle(link, backends, &mut setup, msg) {
            Ok(true) => return Ok(()),
            Ok(false) => {}
            Err(e) => {
                if frame {
                    link.reply(&error_stats(link.rank(), &e))?;
                }
                // Free the renderer (and its device) now.
                setup = None;
                failed = Some(e);
            }
        }
    }
}

fn error_stats(rank: u32, e: &anyhow::Error) -> FrameStats {
    FrameStats {
        rank,
        error: Some(format!("{e:#}")),
        ..Default::default()
    }
}

fn handle(
    link: &mut dyn Link,
    backends: usize,
    setup: &mut Option<Setup>,
    msg: ToBackend,
) -> Result<bool> {
    match msg {
        ToBackend::Quit => return Ok(true),
        ToBackend::Setup {
            scene,
            display,
            out_dir,
            float,
            sync_io,
        } => {
            let assignment = display.assignment(backends)?;
            let mine = assignment[link.rank() as usize - 1].clone();
            let mut renderer = Renderer::new(&scene.volume, &scene.render)?;
            renderer.sync_io = sync_io;
            let screen = &display.screen;
            renderer.set_lightfield((screen.angular_accuracy_deg > 0.0).then_some(
                crate::loader::LightField {
                    pixel_size: screen.pixel_size,
                    angular_accuracy_deg: screen.angular_accuracy_deg,
                },
            ));
            *setup = Some(Setup {
                display,
                mine,
                out_dir,
                float,
                renderer,
            });
        }
        ToBackend::TransferFunction { version, tf } => {
            let s = setup.as_mut().context("transfer function before setup")?;
            s.renderer.set_transfer_function(version, &tf)?;
        }
        ToBackend::Frame(state) => {
            fault_injection(link.rank(), state.frame);
            let s = setup.as_mut().context("frame before setup")?;
            let mut stats = render_frame(s, &state)?;
            stats.rank = link.rank();
            link.reply(&stats)?;
        }
    }
    Ok(false)
}

/// The views of this back end's projectors for a frame.
pub fn views_for(display: &Display, mine: &[usize], state: &FrameState) -> Vec<View> {
    let all = display.views(state.eta);
    mine.iter()
        .map(|&i| View {
            observer: state.observer,
            ..all[i]
        })
        .collect()
}

fn render_frame(s: &mut Setup, state: &FrameState) -> Result<FrameStats> {
    let start = Instant::now();
    if s.renderer.tf_version() != Some(state.tf_version) {
        anyhow::bail!(
            "frame {}: transfer function version {} was never sent",
            state.frame,
            state.tf_version
        );
    }
    let views = views_for(&s.display, &s.mine, state);
    let frame = s
        .renderer
        .frame(state.frame, &state.placement, &views, &state.render)?;
    let mut stats = frame.stats;
    let t = Instant::now();
    if let Some(dir) = &s.out_dir {
        let fdir = dir.join(format!("frame_{:05}", state.frame));
        std::fs::create_dir_all(&fdir)
            .with_context(|| format!("{}: cannot create", fdir.display()))?;
        for (img, &pi) in frame.images.iter().zip(&s.mine) {
            let p = &s.display.projectors[pi];
            let [w, h] = p.resolution;
            output::write_png(&fdir.join(format!("{}.png", p.id)), w, h, img)?;
            if s.float {
                output::write_npy(&fdir.join(format!("{}.npy", p.id)), w, h, img)?;
            }
        }
    }
    stats.output_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.total_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(stats)
}

/// `PARALLAX_FAULT=exit:<rank>:<frame>` makes back end `<rank>` die at frame
/// `<frame>` without a word, as a crashed node would: how the tests check
/// that a run with a dead back end ends with an error naming it instead of
/// hanging.
fn fault_injection(rank: u32, frame: u64) {
    if let Ok(spec) = std::env::var("PARALLAX_FAULT") {
        let parts: Vec<&str> = spec.split(':').collect();
        if parts.len() == 3
            && parts[0] == "exit"
            && parts[1].parse() == Ok(rank)
            && parts[2].parse() == Ok(frame)
        {
            std::process::exit(70);
        }
    }
}
