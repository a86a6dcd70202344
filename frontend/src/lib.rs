//! Parallax front end: the coordinator (docs/design.md "Process model"). It reads
//! the scene, sends the large state once, then every frame broadcasts a small
//! `FrameState`, waits for every back end's `FrameStats` (frames are
//! swap-locked) and writes them to `stats.jsonl`.

pub mod cluster;
pub mod live;
pub mod script;

use anyhow::{bail, Context, Result};
use parallax_common::config::{Display, Scene};
use parallax_common::protocol::{FrameState, FrameStats, HeldBack, ToBackend, Transport};
use parallax_common::tf::TransferFunction;
use script::Script;
use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub scene: PathBuf,
    /// Overrides the scene's display.
    pub display: Option<PathBuf>,
    /// Frames to render (0: the script's length, or without a script until
    /// the cut has converged, at most [`CONVERGE_FRAMES`]).
    pub frames: u64,
    pub out: Option<PathBuf>,
    pub float: bool,
    pub sync_io: bool,
    /// An interaction script (keyframes); its length sets the frame count
    /// unless `frames` is given.
    pub script: Option<PathBuf>,
    /// Print a line per frame.
    pub verbose: bool,
    /// How long to wait for a back end's reply before naming it and ending
    /// the run (`None`: forever).
    pub watchdog: Option<std::time::Duration>,
    /// Show every frame on the display's outputs, all back ends together
    /// (swap lock: each presents frame N once every back end has rendered
    /// it), and keep the last one up this many seconds after the run.
    pub present: Option<f64>,
}

/// Frames rendered at most when none are asked for and no script sets them.
pub const CONVERGE_FRAMES: u64 = 256;

/// What a run produced, a few numbers per frame (every back end's own
/// figures go to `stats.jsonl`, not to memory: a long run stays small).
#[derive(Debug, Default)]
pub struct RunSummary {
    /// Per frame: wall time on the front end from broadcast to the last
    /// reply (ms), and the bytes of the broadcast FrameState message.
    pub wall_ms: Vec<f64>,
    pub state_bytes: Vec<usize>,
    /// Per frame: front-end wall time not spent inside the slowest back
    /// end's frame — what coordination (broadcast, gather, swap lock) costs.
    pub coordination_ms: Vec<f64>,
    /// Per frame with `present`: the latest minus the earliest back end's
    /// present time (ms).
    pub present_spread_ms: Vec<f64>,
}

/// The display a scene renders to.
pub fn load_display(scene: &Scene, over: Option<&PathBuf>) -> Result<Display> {
    let path = over
        .or(scene.display.as_ref())
        .context("no display: give --display or set `display` in the scene file")?;
    Display::load(path)
}

/// Runs a whole session over `transport` and tells the back ends to quit at
/// the end (also after an error, so no back end is left waiting; after a
/// watchdog error the caller ends the unresponsive ranks).
pub fn run(opts: &RunOptions, transport: &mut dyn Transport) -> Result<RunSummary> {
    session(transport, opts.watchdog, |t| run_frames(opts, t))
}

/// Runs `body` as a session over `transport` with the watchdog set, then
/// tells the back ends to quit (also after an error, so that none is left
/// waiting; after a watchdog error the launcher ends the unresponsive
/// ranks, which cannot take part in a broadcast).
pub fn session<T>(
    transport: &mut dyn Transport,
    watchdog: Option<std::time::Duration>,
    body: impl FnOnce(&mut dyn Transport) -> Result<T>,
) -> Result<T> {
    transport.set_watchdog(watchdog);
    let result = body(transport);
    let unresponsive =
        matches!(&result, Err(e) if e.is::<parallax_common::protocol::Unresponsive>());
    if !unresponsive {
        let _ = transport.broadcast(&ToBackend::Quit);
    }
    result
}

/// A stats file in `dir` (created), written line by line.
pub(crate) fn stats_writer(dir: &Path, name: &str) -> Result<std::io::BufWriter<std::fs::File>> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let p = dir.join(name);
    let f = std::fs::File::create(&p).with_context(|| format!("{}: cannot create", p.display()))?;
    Ok(std::io::BufWriter::new(f))
}

/// Every back end's figures of one frame as JSON lines, flushed: a run that
/// is killed keeps the figures of every frame it finished.
pub(crate) fn write_stats(f: &mut impl Write, stats: &[FrameStats]) -> Result<()> {
    for s in stats {
        serde_json::to_writer(&mut *f, s)?;
        f.write_all(b"\n")?;
    }
    f.flush()?;
    Ok(())
}

fn run_frames(opts: &RunOptions, transport: &mut dyn Transport) -> Result<RunSummary> {
    let scene = Scene::load(&opts.scene)?;
    let display = load_display(&scene, opts.display.as_ref())?;
    display.assignment(transport.backends())?;
    let tf = TransferFunction::load(&scene.transfer_function)?;
    let create = |name: &str| {
        opts.out
            .as_deref()
            .map(|d| stats_writer(d, name))
            .transpose()
    };
    // stats.jsonl: each back end's FrameStats; frontend.jsonl: the
    // coordinator's own figures per frame.
    let mut stats_file = create("stats.jsonl")?;
    let mut frontend_file = create("frontend.jsonl")?;
    setup(
        transport,
        &ToBackend::Setup {
            scene: scene.clone(),
            display: display.clone(),
            out_dir: opts.out.clone(),
            float: opts.float,
            sync_io: opts.sync_io,
            present: opts.present.is_some(),
        },
    )
    .with_context(|| opts.scene.display().to_string())?;
    transport.broadcast(&ToBackend::TransferFunction { version: 1, tf })?;
    transport.broadcast(&ToBackend::Tools {
        version: 1,
        tools: scene.tools.clone(),
    })?;
    let script = opts.script.as_deref().map(Script::load).transpose()?;
    if let (Some(sc), Some(path)) = (&script, &opts.script) {
        if let Some(i) = sc.layer_indices().find(|&i| i >= scene.layers.len()) {
            anyhow::bail!(
                "{}: layer_functions: index {i}, but {} has {} layers",
                path.display(),
                opts.scene.display(),
                scene.layers.len()
            );
        }
    }
    if let (Some(sc), Some(path)) = (&script, &opts.script) {
        if sc.last_time() as usize >= scene.steps() {
            anyhow::bail!(
                "{}: time: step {}, but {} has {} time step{}",
                path.display(),
                sc.last_time(),
                opts.scene.display(),
                scene.steps(),
                if scene.steps() == 1 { "" } else { "s" }
            );
        }
    }
    let until_converged = opts.frames == 0 && script.is_none();
    let frames = match (opts.frames, &script) {
        (0, Some(s)) => s.frames,
        (0, None) => CONVERGE_FRAMES,
        (n, _) => n,
    };
    let mut summary = RunSummary::default();
    let mut notes = Notes::default();
    let mut sent = Sent {
        tools: scene.tools.clone(),
        tools_version: 1,
        tf_version: 1,
        tf_switch: None,
        layer_files: vec![None; scene.layers.len()],
        layer_version: 0,
    };
    for frame in 0..frames {
        let mut state = FrameState {
            frame,
            placement: scene.placement,
            observer: display.observer.position,
            eta: scene.render.eta,
            render: scene.render.clone(),
            tf_version: sent.tf_version,
            tools_version: sent.tools_version,
            stream: Vec::new(),
            pick: None,
            grow: None,
            layers: Vec::new(),
            step: 0,
        };
        if let Some(sc) = &script {
            sent.script(sc, &scene, &display, &mut state, transport)?;
        }
        let start = std::time::Instant::now();
        let msg = ToBackend::Frame(state);
        summary
            .state_bytes
            .push(parallax_common::protocol::encode(&msg)?.len());
        transport.broadcast(&msg)?;
        let mut stats = transport.gather()?;
        summary.wall_ms.push(start.elapsed().as_secs_f64() * 1e3);
        if let Some(bad) = stats.iter().find(|s| s.error.is_some()) {
            bail!(
                "back end {} failed: {}",
                bad.rank,
                bad.error.as_deref().unwrap_or("")
            );
        }
        answers(&stats, frame)?;
        if opts.present.is_some() {
            let spread = swap(transport, frame, &mut stats)?;
            summary.present_spread_ms.push(spread);
        }
        notes.report(&stats);
        // Both files are flushed every frame: a run that is killed keeps
        // the figures of every frame it finished.
        if let Some(f) = stats_file.as_mut() {
            write_stats(f, &stats)?;
        }
        let wall = *summary.wall_ms.last().unwrap();
        let slowest = stats.iter().map(|s| s.total_ms).fold(0.0, f64::max);
        summary.coordination_ms.push((wall - slowest).max(0.0));
        if let Some(f) = frontend_file.as_mut() {
            write_frontend_line(f, frame, &summary, slowest, stats.len())?;
        }
        if opts.verbose {
            println!("{}", frame_line(frame, &stats, wall));
        }
        let converged = stats.iter().all(|s| s.adequate && s.uploaded == 0);
        if until_converged && converged {
            break;
        }
        if until_converged && frame + 1 == frames {
            eprintln!("note: the cut had not converged after {frames} frames");
        }
    }
    if let Some(hold) = opts.present.filter(|&h| h > 0.0) {
        // The windows keep showing the last frame until the back ends quit.
        std::thread::sleep(std::time::Duration::from_secs_f64(hold));
    }
    for f in [stats_file, frontend_file].into_iter().flatten() {
        f.into_inner()
            .map_err(|e| anyhow::anyhow!("writing stats: {}", e.error()))?;
    }
    if opts.verbose && !summary.wall_ms.is_empty() {
        println!("{}", summary.line());
    }
    Ok(summary)
}

/// What the coordinator has sent the back ends: the tools and the
/// transfer function, each with its version, and which of the script's
/// transfer functions is current.
struct Sent {
    tools: Vec<parallax_common::tools::Tool>,
    tools_version: u64,
    tf_version: u64,
    tf_switch: Option<usize>,
    /// The layers' function files in force (`None`: the scene's).
    layer_files: Vec<Option<std::path::PathBuf>>,
    layer_version: u64,
}

impl Sent {
    /// The script's frame: placement, observer, η and knobs in `state`;
    /// tools and a transfer function are broadcast when they change, not
    /// every frame.
    fn script(
        &mut self,
        sc: &Script,
        scene: &Scene,
        display: &Display,
        state: &mut FrameState,
        transport: &mut dyn Transport,
    ) -> Result<()> {
        let frame = state.frame;
        let st = sc.at(
            frame,
            &scene.placement,
            display.observer.position,
            scene.render.eta,
        );
        state.placement = st.placement;
        state.observer = st.observer;
        state.eta = st.eta;
        state.render.gamma = sc.gamma(frame, scene.render.gamma);
        state.render.overlay.cursor = sc.cursor(frame, scene.render.overlay.cursor);
        state.render.overlay.show = sc.overlay(frame, scene.render.overlay.show);
        state.render.accuracy = sc.accuracy(frame, scene.render.accuracy);
        state.render.step_factor = sc.step_factor(frame, scene.render.step_factor);
        state.step = sc.time(frame);
        state.layers = sc.layers(frame);
        // Tools are sent when they change, not every frame.
        let now = sc.tools(frame, &scene.tools)?;
        if now != self.tools {
            self.tools = now;
            self.tools_version += 1;
            transport.broadcast(&ToBackend::Tools {
                version: self.tools_version,
                tools: self.tools.clone(),
            })?;
            state.tools_version = self.tools_version;
        }
        // A transfer function is sent when it changes, not every frame.
        if let Some((i, path)) = st.tf {
            if self.tf_switch != Some(i) {
                self.tf_switch = Some(i);
                self.tf_version += 1;
                let tf = TransferFunction::load(&path)?;
                transport.broadcast(&ToBackend::TransferFunction {
                    version: self.tf_version,
                    tf,
                })?;
                state.tf_version = self.tf_version;
            }
        }
        // So are the layers' functions.
        let files = sc.layer_functions(frame, scene.layers.len());
        if files != self.layer_files {
            let tfs = files
                .iter()
                .zip(&scene.layers)
                .enumerate()
                .map(|(i, (f, l))| {
                    f.as_ref()
                        .map(|p| {
                            l.load_function_from(p)
                                .with_context(|| format!("layer_functions: layer {i}"))
                        })
                        .transpose()
                })
                .collect::<Result<Vec<_>>>()?;
            self.layer_files = files;
            self.layer_version += 1;
            transport.broadcast(&ToBackend::LayerFunctions {
                version: self.layer_version,
                tfs,
            })?;
        }
        Ok(())
    }
}

/// The coordinator's own figures of a frame, one line of frontend.jsonl.
fn write_frontend_line(
    f: &mut impl Write,
    frame: u64,
    summary: &RunSummary,
    slowest: f64,
    backends: usize,
) -> Result<()> {
    let line = serde_json::json!({
        "frame": frame,
        "wall_ms": summary.wall_ms.last().unwrap(),
        "slowest_backend_ms": slowest,
        "coordination_ms": summary.coordination_ms.last().unwrap(),
        "state_bytes": summary.state_bytes.last().unwrap(),
        "backends": backends,
        "present_spread_ms": summary.present_spread_ms.last(),
    });
    serde_json::to_writer(&mut *f, &line)?;
    f.write_all(b"\n")?;
    f.flush()?;
    Ok(())
}

impl RunSummary {
    /// The run's averages in one line.
    fn line(&self) -> String {
        let n = self.wall_ms.len() as f64;
        let wall = self.wall_ms.iter().sum::<f64>() / n;
        let coord = self.coordination_ms.iter().sum::<f64>() / n;
        format!(
            "{} frames: {:.1} ms per frame on average, coordination {:.2} ms ({:.1}%), FrameState {} bytes",
            self.wall_ms.len(),
            wall,
            coord,
            100.0 * coord / wall.max(1e-9),
            self.state_bytes.iter().max().unwrap()
        ) + &self.spread_line()
    }

    /// The swap lock's spread over the run: median and largest (ms).
    fn spread_line(&self) -> String {
        if self.present_spread_ms.is_empty() {
            return String::new();
        }
        let mut v = self.present_spread_ms.clone();
        v.sort_by(f64::total_cmp);
        format!(
            "; present spread across ranks {:.2} ms median, {:.2} ms largest",
            v[v.len() / 2],
            v[v.len() - 1]
        )
    }
}

/// Sends the session's set-up and waits until every back end has taken it.
/// Each answers with what it runs (protocol, build) and renders (its
/// database's identity): a back end that failed, or that differs from the
/// coordinator, or whose database differs from the first back end's, is
/// named before the first frame.
pub(crate) fn setup(transport: &mut dyn Transport, msg: &ToBackend) -> Result<()> {
    use parallax_common::protocol::{BUILD, PROTOCOL_VERSION};
    transport.broadcast(msg)?;
    let replies = transport.gather()?;
    if let Some(bad) = replies.iter().find(|s| s.error.is_some()) {
        bail!(
            "back end {} failed to set up: {}",
            bad.rank,
            bad.error.as_deref().unwrap_or("")
        );
    }
    let mut first: Option<(u32, u64)> = None;
    for r in &replies {
        let Some(ready) = &r.ready else {
            bail!(
                "back end {} answered the set-up without saying what it runs (another build?)",
                r.rank
            );
        };
        if ready.protocol != PROTOCOL_VERSION || ready.build != BUILD {
            bail!(
                "back end {} runs protocol {} of parallax {}, the coordinator protocol {PROTOCOL_VERSION} of parallax {BUILD}: run one build on every rank",
                r.rank,
                ready.protocol,
                ready.build
            );
        }
        match first {
            None => first = Some((r.rank, ready.database)),
            Some((k, d)) if d != ready.database => bail!(
                "back end {} reads another database than back end {k} (identity {:016x} against {d:016x}): every rank must read the same .pxo",
                r.rank,
                ready.database
            ),
            Some(_) => {}
        }
    }
    Ok(())
}

/// Every reply answers `frame` (a reply for another frame is a rank out of
/// step, named).
pub(crate) fn answers(replies: &[FrameStats], frame: u64) -> Result<()> {
    match replies.iter().find(|s| s.frame != frame) {
        Some(r) => bail!(
            "back end {} answered frame {} when asked for frame {frame}",
            r.rank,
            r.frame
        ),
        None => Ok(()),
    }
}

/// The swap lock (G10 §5): every back end has rendered `frame` (its stats
/// are in); tell them all to present it, gather when each did, and put
/// those times into the frame's stats. Returns the spread across back ends
/// (ms).
pub(crate) fn swap(
    transport: &mut dyn Transport,
    frame: u64,
    stats: &mut [FrameStats],
) -> Result<f64> {
    transport.broadcast(&ToBackend::Present { frame })?;
    let shown = transport.gather()?;
    if let Some(bad) = shown.iter().find(|s| s.error.is_some()) {
        bail!(
            "back end {} failed to present frame {frame}: {}",
            bad.rank,
            bad.error.as_deref().unwrap_or("")
        );
    }
    answers(&shown, frame)?;
    for s in stats.iter_mut() {
        if let Some(p) = shown.iter().find(|p| p.rank == s.rank) {
            s.present_us = p.present_us;
            s.present_ms = p.present_ms;
            s.present_direct = p.present_direct;
        }
    }
    let times = shown.iter().map(|s| s.present_us);
    let spread = times.clone().max().unwrap_or(0) - times.min().unwrap_or(0);
    Ok(spread as f64 / 1e3)
}

/// What the user is told once per run, not once per frame: limits that held
/// refinement back (each, the first time a back end reports it) and bricks
/// that could not be read.
#[derive(Default)]
pub(crate) struct Notes {
    held_back: BTreeSet<HeldBack>,
    bad_bricks: BTreeSet<String>,
}

impl Notes {
    pub(crate) fn report(&mut self, stats: &[FrameStats]) {
        for s in stats {
            for &h in &s.held_back {
                if self.held_back.insert(h) {
                    eprintln!(
                        "note: frame {}, rank {}: refinement held back: {}",
                        s.frame,
                        s.rank,
                        h.advice()
                    );
                }
            }
            for b in &s.bad_bricks {
                if self.bad_bricks.insert(b.clone()) {
                    eprintln!(
                        "warning: rank {}: {b}; its parent stays a leaf, the run goes on",
                        s.rank
                    );
                }
            }
        }
    }
}

/// One line per frame: wall time, the slowest back end, the bricks per back
/// end (G10 §6 reports 1549 average / 2087 max).
pub fn frame_line(frame: u64, stats: &[FrameStats], wall_ms: f64) -> String {
    let slowest = stats
        .iter()
        .max_by(|a, b| a.total_ms.total_cmp(&b.total_ms))
        .expect("at least one back end");
    let bricks: Vec<u64> = stats.iter().map(|s| s.cut_leaves_with_data).collect();
    let avg = bricks.iter().sum::<u64>() as f64 / bricks.len() as f64;
    format!(
        "frame {frame:>5}: {wall_ms:>8.1} ms (slowest rank {} {:.1} ms), bricks per rank avg {avg:.0} max {}, uploaded {}, read {:.1} MB{}",
        slowest.rank,
        slowest.total_ms,
        bricks.iter().max().unwrap(),
        stats.iter().map(|s| s.uploaded).sum::<u64>(),
        stats.iter().map(|s| s.bytes_read).sum::<u64>() as f64 / 1e6,
        if stats.iter().all(|s| s.adequate) { ", converged" } else { "" }
    )
}
