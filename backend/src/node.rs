//! A back-end process (or thread): receives the front end's messages,
//! renders its projectors' views each frame, writes their images, replies
//! with the frame's figures (docs/design.md "Process model").

use crate::output;
use crate::present::Presenter;
use crate::render::Renderer;
use anyhow::{Context, Result};
use parallax_common::camera::View;
use parallax_common::config::Display;
use parallax_common::paths::file_in;
use parallax_common::protocol::{
    FrameState, FrameStats, Link, Malformed, Ready, StreamImage, ToBackend, BUILD, PROTOCOL_VERSION,
};
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
    /// With `--present`: the windows, and the last frame's images, shown
    /// when the swap lock says so. Declared before the renderer, whose
    /// device the surfaces belong to.
    presenter: Option<Presenter>,
    pending: Vec<Vec<[f32; 4]>>,
    /// The last frame's images are those in the ray caster's image buffer
    /// (not filtered on the CPU by frame reconstruction).
    on_device: bool,
    /// Each of its projectors' calibration (warp and blend), if any.
    calibrations: Vec<Option<crate::calibrate::Calibrated>>,
    /// A Looking Glass's interleaving, made with the first panel.
    interleaver: Option<crate::lenticular::Interleaver>,
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
                ToBackend::Setup { .. } | ToBackend::Frame(_) | ToBackend::Present { .. } => {
                    link.reply(&error_stats(link.rank(), e))?
                }
                _ => {}
            }
            continue;
        }
        // The front end waits for an answer to these.
        let frame = matches!(
            msg,
            ToBackend::Setup { .. } | ToBackend::Frame(_) | ToBackend::Present { .. }
        );
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
            present,
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
            let mut renderer =
                Renderer::with_layers(&scene.volume, &scene.layers, &scene.render, &req)?;
            renderer.sync_io = sync_io;
            renderer.set_series(&scene.series)?;
            let screen = &display.screen;
            renderer.set_lightfield((screen.angular_accuracy_deg > 0.0).then_some(
                crate::loader::LightField {
                    pixel_size: screen.pixel_size,
                    angular_accuracy_deg: screen.angular_accuracy_deg,
                },
            ));
            let calibrations = mine
                .iter()
                .map(|&p| {
                    let pr = &display.projectors[p];
                    pr.calibration
                        .as_ref()
                        .map(|c| {
                            crate::calibrate::Calibrated::load(c, &format!("projector {}", pr.id))
                        })
                        .transpose()
                })
                .collect::<Result<Vec<_>>>()?;
            let presenter = if present {
                Some(Presenter::open(renderer.gpu(), &display, &mine)?)
            } else {
                None
            };
            let mut ready = Ready {
                protocol: PROTOCOL_VERSION,
                build: BUILD.to_string(),
                database: renderer.db().identity(),
            };
            setup_fault(link.rank(), &mut ready);
            let rank = link.rank();
            *setup = Some(Setup {
                display,
                mine,
                out_dir,
                float,
                presenter,
                pending: Vec::new(),
                on_device: false,
                calibrations,
                interleaver: None,
                renderer,
            });
            link.reply(&FrameStats {
                rank,
                ready: Some(ready),
                ..Default::default()
            })?;
        }
        ToBackend::TransferFunction { version, tf } => {
            let s = setup.as_mut().context("transfer function before setup")?;
            s.renderer.set_transfer_function(version, &tf)?;
        }
        ToBackend::LayerFunctions { version: _, tfs } => {
            let s = setup
                .as_mut()
                .context("layer transfer functions before setup")?;
            s.renderer.set_layer_functions(&tfs)?;
        }
        ToBackend::Tools { version, tools } => {
            let s = setup.as_mut().context("tools before setup")?;
            s.renderer.set_tools(version, &tools)?;
        }
        ToBackend::Frame(state) => {
            fault_injection(link.rank(), state.frame);
            let s = setup.as_mut().context("frame before setup")?;
            s.renderer.set_step(state.step as usize)?;
            let mut stats = render_frame(s, &state)?;
            stats.rank = link.rank();
            if let (Some([origin, dir]), 1) = (state.pick, link.rank()) {
                match state.grow {
                    Some(tolerance) => {
                        stats.grown =
                            s.renderer
                                .grow_band(&state.placement, origin, dir, tolerance)?;
                    }
                    None => stats.pick = s.renderer.pick(&state.placement, origin, dir)?,
                }
            }
            stats.rss_bytes = parallax_common::resident_bytes();
            link.reply(&stats)?;
        }
        ToBackend::Present { frame } => {
            let s = setup.as_mut().context("present before setup")?;
            let p = s
                .presenter
                .as_mut()
                .context("present: this session was not set up to present")?;
            let t = Instant::now();
            // Straight from the device where nothing is done to the images
            // on the CPU (a calibration, a Looking Glass's panel, frame
            // reconstruction's CPU filter).
            let plain = s.on_device
                && s.display.looking_glass.is_none()
                && s.calibrations.iter().all(Option::is_none);
            let direct = plain && p.direct();
            if direct {
                let first: Vec<u64> = s
                    .mine
                    .iter()
                    .scan(0u64, |at, &i| {
                        let [w, h] = s.display.projectors[i].resolution;
                        let here = *at;
                        *at += w as u64 * h as u64;
                        Some(here)
                    })
                    .collect();
                p.present_direct(s.renderer.gpu(), s.renderer.image_buffer(), &first)?;
            } else {
                p.present(s.renderer.gpu(), &s.pending)?;
            }
            let since_epoch = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap_or_default();
            link.reply(&FrameStats {
                rank: link.rank(),
                frame,
                present_us: since_epoch.as_micros() as u64,
                present_ms: t.elapsed().as_secs_f64() * 1e3,
                present_direct: direct,
                ..Default::default()
            })?;
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
    s.renderer.set_layer_controls(&state.layers)?;
    let views = views_for(&s.display, &s.mine, state);
    let mut frame = s
        .renderer
        .frame(state.frame, &state.placement, &views, &state.render)?;
    let mut stats = std::mem::take(&mut frame.stats);
    let t = Instant::now();
    for ((img, &pi), c) in frame.images.iter_mut().zip(&s.mine).zip(&s.calibrations) {
        if let Some(c) = c {
            *img = c.apply(img, s.display.projectors[pi].resolution);
        }
    }
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
    let panel = looking_glass_panel(s, &frame.images, state.frame)?;
    s.on_device = !state.render.reconstruction || s.renderer.reconstruct_on_gpu;
    if s.presenter.is_some() {
        s.pending = match panel {
            Some(p) => vec![p],
            None => frame.images,
        };
    }
    stats.output_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.total_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(stats)
}

/// A Looking Glass's panel from this frame's views (this back end renders
/// them all), written as `panel.png` beside the views.
fn looking_glass_panel(
    s: &mut Setup,
    images: &[Vec<[f32; 4]>],
    frame: u64,
) -> Result<Option<Vec<[f32; 4]>>> {
    let Some(lg) = &s.display.looking_glass else {
        return Ok(None);
    };
    anyhow::ensure!(
        s.mine.len() == s.display.projectors.len(),
        "a Looking Glass's views are rendered by one back end (run it with one)"
    );
    if s.interleaver.is_none() {
        s.interleaver = Some(crate::lenticular::Interleaver::new(s.renderer.gpu())?);
    }
    let il = s.interleaver.as_ref().expect("made above");
    let size = s.display.projectors[0].resolution;
    let panel = il.panel(s.renderer.gpu(), lg, images, size)?;
    if let Some(dir) = &s.out_dir {
        let [w, h] = lg.screen;
        let path = dir.join(format!("frame_{frame:05}")).join("panel.png");
        output::write_png(&path, w, h, &panel)?;
    }
    Ok(Some(panel))
}

/// `PARALLAX_FAULT=<kind>:<rank>:<frame>` makes back end `<rank>` fail at
/// frame `<frame>` the way real nodes fail, so the tests can check that each
/// failure ends the run with an error naming the rank instead of hanging:
/// `exit` dies without a word (a crashed node), `panic` panics inside the
/// frame (a bug), `stop` stops the process with SIGSTOP (a node that hangs).
/// `PARALLAX_FAULT=protocol:<rank>:0` or `database:<rank>:0`: back end
/// `<rank>` says it speaks another protocol, or renders another database,
/// as a rank of another build or with another file would.
fn setup_fault(rank: u32, ready: &mut Ready) {
    let Ok(spec) = std::env::var("PARALLAX_FAULT") else {
        return;
    };
    let parts: Vec<&str> = spec.split(':').collect();
    if parts.len() != 3 || parts[1].parse() != Ok(rank) {
        return;
    }
    match parts[0] {
        "protocol" => ready.protocol += 1,
        "database" => ready.database ^= 1,
        _ => {}
    }
}

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
            grow: None,
            layers: Vec::new(),
            step: 0,
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
