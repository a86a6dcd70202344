//! A back-end process (or thread): receives the front end's messages,
//! renders its projectors' views each frame, writes their images, replies
//! with the frame's figures (docs/design.md "Process model").

use crate::output;
use crate::render::Renderer;
use anyhow::{Context, Result};
use parallax_common::camera::View;
use parallax_common::config::Display;
use parallax_common::paths::file_in;
use parallax_common::protocol::{FrameState, FrameStats, Link, Malformed, StreamImage, ToBackend};
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::time::Instant;

thread_local! {
    static CATCHING: Cell<bool> = const { Cell::new(false) };
}

/// Whether the current thread is inside a back end's message handling, where
/// a panic is caught and becomes an error reply naming the rank (a process
/// panic hook leaves such panics alone).
pub fn catching_panics() -> bool {
    CATCHING.with(|c| c.get())
}

/// Runs `f`, turning a panic into an error.
fn catch_panic<T>(f: impl FnOnce() -> Result<T>) -> Result<T> {
    let before = CATCHING.with(|c| c.replace(true));
    let r = catch_unwind(AssertUnwindSafe(f));
    CATCHING.with(|c| c.set(before));
    r.unwrap_or_else(|payload| {
        let msg = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(no message)".into());
        Err(anyhow::anyhow!("internal error (panic): {msg}"))
    })
}

struct Setup {
    display: Display,
    mine: Vec<usize>,
    out_dir: Option<PathBuf>,
    float: bool,
    renderer: Renderer,
}

/// Serves the front end until it says quit. After an error (or a panic,
/// caught here) the back end keeps answering every frame with that error (so
/// the front end, which waits for every back end each frame, learns which
/// rank failed instead of hanging) until it is told to quit; the error is
/// then returned.
pub fn serve(link: &mut dyn Link, backends: usize) -> Result<()> {
    let mut setup: Option<Setup> = None;
    let mut failed: Option<anyhow::Error> = None;
    loop {
        let msg = match link.receive() {
            Ok(m) => m,
            Err(e) if failed.is_none() && e.is::<Malformed>() => {
                // A message this back end cannot read: say so at once (the
                // front end takes it as this frame's reply and names the
                // rank) and answer every later frame with the same error.
                link.reply(&error_stats(link.rank(), &e))?;
                setup = None;
                failed = Some(e);
                continue;
            }
            Err(e) => return Err(e),
        };
        if let Some(e) = &failed {
            match msg {
                ToBackend::Quit => return Err(failed.take().unwrap()),
                ToBackend::Frame(_) => link.reply(&error_stats(link.rank(), e))?,
                _ => {}
            }
            continue;
        }
        let frame = matches!(msg, ToBackend::Frame(_));
        match catch_panic(|| handle(link, backends, &mut setup, msg)) {
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
            // A projector file may name this back end's GPU; otherwise the
            // node-local rank picks one (embedded: the back-end index).
            let named = mine.iter().find_map(|&p| {
                let pr = &display.projectors[p];
                pr.adapter
                    .clone()
                    .map(|a| (a, format!("projector {}: adapter", pr.id)))
            });
            let req = crate::gpu::AdapterRequest::from_env(named, link.rank() as usize - 1);
            let mut renderer = Renderer::with_adapter(&scene.volume, &scene.render, &req)?;
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
        ToBackend::Tools { version, tools } => {
            let s = setup.as_mut().context("tools before setup")?;
            s.renderer.set_tools(version, &tools)?;
        }
        ToBackend::Frame(state) => {
            fault_injection(link.rank(), state.frame);
            let s = setup.as_mut().context("frame before setup")?;
            let mut stats = render_frame(s, &state)?;
            stats.rank = link.rank();
            if let (Some([origin, dir]), 1) = (state.pick, link.rank()) {
                stats.pick = s.renderer.pick(&state.placement, origin, dir)?;
            }
            stats.rss_bytes = parallax_common::resident_bytes();
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
    if s.renderer.tools_version() != state.tools_version {
        anyhow::bail!(
            "frame {}: tool set version {} was never sent",
            state.frame,
            state.tools_version
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
            // Checked when the display was loaded; checked again here, where
            // the id becomes a file name, whatever sent the display.
            let what = format!("projector id '{}'", p.id);
            output::write_png(&file_in(&fdir, &format!("{}.png", p.id), &what)?, w, h, img)?;
            if s.float {
                output::write_npy(&file_in(&fdir, &format!("{}.npy", p.id), &what)?, w, h, img)?;
            }
        }
    }
    for (img, &pi) in frame.images.iter().zip(&s.mine) {
        if state.stream.contains(&(pi as u32)) {
            let [width, height] = s.display.projectors[pi].resolution;
            stats.images.push(StreamImage {
                projector: pi as u32,
                width,
                height,
                rgb8: output::rgb8(img),
            });
        }
    }
    stats.output_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.total_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(stats)
}

/// `PARALLAX_FAULT=<kind>:<rank>:<frame>` makes back end `<rank>` fail at
/// frame `<frame>` the way real nodes fail, so the tests can check that each
/// failure ends the run with an error naming the rank instead of hanging:
/// `exit` dies without a word (a crashed node), `panic` panics inside the
/// frame (a bug), `stop` stops the process with SIGSTOP (a node that hangs).
fn fault_injection(rank: u32, frame: u64) {
    let Ok(spec) = std::env::var("PARALLAX_FAULT") else {
        return;
    };
    let parts: Vec<&str> = spec.split(':').collect();
    if parts.len() != 3 || parts[1].parse() != Ok(rank) || parts[2].parse() != Ok(frame) {
        return;
    }
    match parts[0] {
        "exit" => std::process::exit(70),
        "panic" => panic!("fault injection at frame {frame}"),
        "stop" => {
            // SAFETY: raise only signals this process.
            unsafe {
                libc::raise(libc::SIGSTOP);
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;

    struct Scripted {
        inbox: VecDeque<Result<ToBackend>>,
        replies: Vec<FrameStats>,
    }

    impl Link for Scripted {
        fn rank(&self) -> u32 {
            1
        }
        fn receive(&mut self) -> Result<ToBackend> {
            self.inbox
                .pop_front()
                .unwrap_or_else(|| Err(anyhow::anyhow!("the front end has stopped")))
        }
        fn reply(&mut self, stats: &FrameStats) -> Result<()> {
            self.replies.push(stats.clone());
            Ok(())
        }
    }

    /// A message the back end cannot read is answered at once with an error
    /// naming it (the front end must not wait for its watchdog), and so is
    /// every later frame, until quit.
    #[test]
    fn an_unreadable_message_is_answered_with_an_error() {
        let frame = ToBackend::Frame(FrameState {
            frame: 0,
            placement: parallax_common::camera::Placement {
                center: [0.0; 3],
                rotation_deg: [0.0; 3],
                size: 1.0,
            },
            observer: [0.0, 0.0, 1.0],
            eta: 0.0,
            render: Default::default(),
            tf_version: 1,
            tools_version: 1,
            stream: Vec::new(),
            pick: None,
        });
        let mut link = Scripted {
            inbox: VecDeque::from([
                Err(Malformed("truncated".into()).into()),
                Ok(frame),
                Ok(ToBackend::Quit),
            ]),
            replies: Vec::new(),
        };
        let e = serve(&mut link, 1).unwrap_err();
        assert!(e.to_string().contains("malformed"), "{e}");
        assert_eq!(link.replies.len(), 2);
        for r in &link.replies {
            assert!(r
                .error
                .as_deref()
                .unwrap()
                .contains("malformed protocol message"));
        }
    }

    /// A panic inside a frame becomes an error reply, not a dead thread.
    #[test]
    fn a_panic_becomes_an_error() {
        let e = catch_panic(|| -> Result<()> { panic!("boom") }).unwrap_err();
        assert!(e.to_string().contains("boom"), "{e}");
        assert!(!catching_panics());
    }
}
