//! The live coordinator (`parallax serve`): a page in a browser drives the
//! display while the back ends render (G10 §6: people move the scene and
//! its tools in front of the wall). The protocol is in
//! `docs/live-protocol.md`.
//!
//! Threads: the coordinator's own thread runs the frame loop over the
//! [`Transport`] (blocking, as in `render`: MPI stays on one thread); a
//! small tokio runtime serves the page and the WebSockets. They share one
//! [`LiveState`] under a mutex: a client's change bumps its version and
//! wakes the frame loop, which renders while the state changed or the cut
//! has not converged and otherwise sleeps on a condition variable (no CPU).
//! Frames reach the clients through a `watch` channel, which holds only the
//! newest: a slow or vanished client misses frames, never stalls the loop.

mod listen;
pub mod record;
mod state;

pub use state::{ClientMsg, LiveState};

use crate::{session, Notes};
use anyhow::{Context, Result};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::StatusCode;
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use futures_util::{SinkExt, StreamExt};
use parallax_common::config::{Display, Scene};
use parallax_common::protocol::{FrameState, StreamImage, ToBackend, Transport};
use parallax_common::tf::TransferFunction;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{broadcast, watch};

/// The page, shipped inside the binary.
const PAGE: &str = include_str!("page.html");

/// What an eye at a position sees on a light field display, from every
/// projector's streamed image (the launcher supplies the simulator):
/// width, height and sRGB 8-bit RGB.
pub type EyeView = fn(&Display, &[StreamImage], [f64; 3]) -> Result<(u32, u32, Vec<u8>)>;

pub struct ServeOptions {
    pub scene: PathBuf,
    pub display: Option<PathBuf>,
    pub bind: SocketAddr,
    /// The access token (None: a random one).
    pub token: Option<String>,
    /// Back ends also write every frame's images here (and the coordinator
    /// `stats.jsonl`), as `render` does.
    pub out: Option<PathBuf>,
    pub sync_io: bool,
    /// Record the whole session, from frame 0, into this folder.
    pub record: Option<PathBuf>,
    /// Where the page's record control writes.
    pub record_dir: PathBuf,
    /// Where a recording stops itself.
    pub record_limits: record::Limits,
    pub watchdog: Option<Duration>,
    /// Told the page's URL once the server listens.
    pub ready: Option<std::sync::mpsc::Sender<String>>,
    pub eye_view: EyeView,
    /// Show every frame on the display's outputs too, swap-locked
    /// (`render --present`).
    pub present: bool,
}

/// Frames rendered after a change before the loop idles even if the cut has
/// not converged (a pool that cannot hold the cut).
const SETTLE_FRAMES: u64 = crate::CONVERGE_FRAMES;

/// A client's send that takes longer than this drops the client.
const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// One streamed frame: its header (JSON) and its PNG.
type Packet = (String, Vec<u8>);

/// What the clients and the frame loop share.
struct Shared {
    live: Mutex<Live>,
    wake: Condvar,
    /// The newest state message (JSON).
    state_tx: watch::Sender<Arc<String>>,
    /// The newest frame: its header (JSON) and PNG.
    frame_tx: watch::Sender<Option<Arc<Packet>>>,
    /// Messages for every client (a recording written, a failed focus).
    notice_tx: broadcast::Sender<String>,
    /// Set once when the session ends, with why.
    ended_tx: watch::Sender<Option<String>>,
    token: String,
    hello: String,
    /// Clients connected now (the session's end waits for each to be told).
    clients: std::sync::atomic::AtomicUsize,
}

struct Live {
    state: LiveState,
    version: u64,
    /// A focus click's ray, for the next frame.
    pick: Option<[[f64; 3]; 2]>,
    /// With `pick`: a band to grow for band picker `.0`, within `.1` of the
    /// transfer function's value span (`grow-band`).
    grow: Option<(usize, f64)>,
    quit: bool,
}

/// Playback of a series: while playing, the step advances when its tick is
/// due (`next_tick`, set one period ahead when playback starts), wrapping
/// after the last, as a new version every page sees; returns the next tick
/// (none when not playing). A loop that falls more than a period behind
/// starts counting again from now rather than skipping steps.
fn play(shared: &Shared, live: &mut Live, next_tick: Option<Instant>) -> Option<Instant> {
    let t = live.state.time;
    if !t.playing {
        return None;
    }
    let period = Duration::from_secs_f64(1.0 / t.rate);
    let now = Instant::now();
    let due = next_tick.unwrap_or(now + period);
    if now < due {
        return Some(due);
    }
    live.state.time.step = (t.step + 1) % live.state.steps.max(1);
    live.version += 1;
    shared
        .state_tx
        .send_replace(Arc::new(Shared::state_message(live)));
    Some(if now >= due + period {
        now + period
    } else {
        due + period
    })
}

impl Shared {
    /// An error message to every client.
    fn notice(&self, message: &str) {
        let msg = serde_json::json!({"type": "error", "message": message});
        let _ = self.notice_tx.send(msg.to_string());
    }

    /// Changes the shared state from the frame loop (a focus, a grown
    /// band): a new version, broadcast, and the loop woken.
    fn change(&self, f: impl FnOnce(&mut LiveState) -> Result<()>) -> Result<()> {
        let mut live = self.live.lock().unwrap();
        f(&mut live.state)?;
        live.version += 1;
        self.state_tx
            .send_replace(Arc::new(Self::state_message(&live)));
        drop(live);
        self.wake.notify_all();
        Ok(())
    }

    fn state_message(live: &Live) -> String {
        serde_json::json!({"type": "state", "version": live.version, "state": live.state})
            .to_string()
    }

    /// Applies one client message; the error is the reply.
    fn apply(&self, text: &str, display: &Display) -> std::result::Result<(), String> {
        let msg: ClientMsg = serde_json::from_str(text).map_err(|e| format!("refused: {e}"))?;
        let mut live = self.live.lock().unwrap();
        match msg {
            ClientMsg::Quit => live.quit = true,
            ClientMsg::Focus { x, y } => {
                let ray = live
                    .state
                    .focus_ray(display, x, y)
                    .map_err(|e| format!("refused: focus: {e}"))?;
                live.pick = Some(ray);
                live.grow = None;
            }
            ClientMsg::GrowBand {
                index,
                x,
                y,
                tolerance,
            } => {
                let tolerance = tolerance.unwrap_or(state::GROW_TOLERANCE);
                live.state
                    .check_grow(index, tolerance)
                    .map_err(|e| format!("refused: {e}"))?;
                let ray = live
                    .state
                    .focus_ray(display, x, y)
                    .map_err(|e| format!("refused: grow-band: {e}"))?;
                live.pick = Some(ray);
                live.grow = Some((index, tolerance));
            }
            other => {
                let next = applied(&live.state, other, display)?;
                if next == live.state {
                    return Ok(());
                }
                live.state = next;
                live.version += 1;
                self.state_tx
                    .send_replace(Arc::new(Self::state_message(&live)));
            }
        }
        self.wake.notify_all();
        Ok(())
    }
}

/// A state-changing message applied to a copy of `state`: the state it
/// leads to, or the refusal the page is sent (the state is unchanged).
fn applied(
    state: &LiveState,
    msg: ClientMsg,
    display: &Display,
) -> std::result::Result<LiveState, String> {
    let mut next = state.clone();
    next.apply(msg, display)
        .map_err(|e| format!("refused: {e:#}"))?;
    Ok(next)
}

/// What the server makes of one page message on its own (the fuzzer's
/// entry, `fuzz/`): the state it leads to, or the refusal. A focus or
/// grow-band is checked up to the ray it would pick; quit changes nothing.
pub fn apply_message(
    state: &LiveState,
    display: &Display,
    text: &str,
) -> std::result::Result<LiveState, String> {
    let msg: ClientMsg = serde_json::from_str(text).map_err(|e| format!("refused: {e}"))?;
    match msg {
        ClientMsg::Quit => Ok(state.clone()),
        ClientMsg::Focus { x, y } => state
            .focus_ray(display, x, y)
            .map(|_| state.clone())
            .map_err(|e| format!("refused: focus: {e}")),
        ClientMsg::GrowBand {
            index,
            x,
            y,
            tolerance,
        } => {
            state
                .check_grow(index, tolerance.unwrap_or(state::GROW_TOLERANCE))
                .map_err(|e| format!("refused: {e}"))?;
            state
                .focus_ray(display, x, y)
                .map(|_| state.clone())
                .map_err(|e| format!("refused: grow-band: {e}"))
        }
        other => applied(state, other, display),
    }
}

/// Runs a live session over `transport` until a client quits, the process
/// is interrupted, or a back end fails (the error names it).
pub fn serve(opts: ServeOptions, transport: &mut dyn Transport) -> Result<()> {
    let watchdog = opts.watchdog;
    session(transport, watchdog, |t| run(opts, t))
}

fn run(opts: ServeOptions, transport: &mut dyn Transport) -> Result<()> {
    let scene = Scene::load(&opts.scene)?;
    let display = crate::load_display(&scene, opts.display.as_ref())?;
    display.assignment(transport.backends())?;
    let tf = TransferFunction::load(&scene.transfer_function)?;
    crate::setup(
        transport,
        &ToBackend::Setup {
            scene: scene.clone(),
            display: display.clone(),
            out_dir: opts.out.clone(),
            float: false,
            sync_io: opts.sync_io,
            present: opts.present,
        },
    )
    .with_context(|| opts.scene.display().to_string())?;
    transport.broadcast(&ToBackend::TransferFunction {
        version: 1,
        tf: tf.clone(),
    })?;
    transport.broadcast(&ToBackend::Tools {
        version: 1,
        tools: scene.tools.clone(),
    })?;
    let mut hello = state::hello(&opts.scene, &scene, &display, &tf, &opts.record_dir);
    hello["record_limits"] = opts.record_limits.json();
    let hello = hello.to_string();
    let layer_tfs = scene
        .layers
        .iter()
        .enumerate()
        .map(|(i, l)| {
            l.load_function().with_context(|| {
                format!(
                    "{}: layer[{i}].{}",
                    opts.scene.display(),
                    l.function_file().0
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let state = LiveState::from_scene(&scene, &display, tf, layer_tfs);
    let token = match &opts.token {
        Some(t) if t.len() < MIN_TOKEN || !t.chars().all(|c| c.is_ascii_alphanumeric()) => {
            anyhow::bail!(
                "--token (or PARALLAX_TOKEN): expected at least {MIN_TOKEN} letters and digits (128 bits), got {} characters",
                t.len()
            )
        }
        Some(t) => t.clone(),
        None => random_token()?,
    };
    let live = Live {
        state,
        version: 1,
        pick: None,
        grow: None,
        quit: false,
    };
    let shared = Arc::new(Shared {
        state_tx: watch::channel(Arc::new(Shared::state_message(&live))).0,
        live: Mutex::new(live),
        wake: Condvar::new(),
        frame_tx: watch::channel(None).0,
        notice_tx: broadcast::channel(16).0,
        ended_tx: watch::channel(None).0,
        token: token.clone(),
        hello,
        clients: Default::default(),
    });

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("parallax-live")
        .enable_all()
        .build()
        .context("cannot start the live server's runtime")?;
    let listener = rt
        .block_on(tokio::net::TcpListener::bind(opts.bind))
        .with_context(|| format!("--bind {}: cannot listen", opts.bind))?;
    let addr = listener.local_addr()?;
    let url = format!("http://{addr}/?token={token}");
    println!("serving {} on {url}", opts.scene.display());
    if !addr.ip().is_loopback() {
        eprintln!(
            "note: the page is reachable from the network at {addr}; only the token guards it"
        );
    }
    if let Some(r) = &opts.ready {
        let _ = r.send(url);
    }
    let app = Router::new()
        .route("/", get(page))
        .route("/ws", get(ws_upgrade))
        .with_state(AppState {
            shared: shared.clone(),
            display: Arc::new(display.clone()),
        });
    let mut ended_rx = shared.ended_tx.subscribe();
    rt.spawn(async move {
        let stop = async move {
            let _ = ended_rx.wait_for(|e| e.is_some()).await;
        };
        listen::serve(listener, app, stop).await;
    });
    {
        let shared = shared.clone();
        rt.spawn(async move {
            if tokio::signal::ctrl_c().await.is_ok() {
                shared.live.lock().unwrap().quit = true;
                shared.wake.notify_all();
            }
        });
    }

    let result = frame_loop(&opts, &scene, &display, &shared, transport);
    let why = match &result {
        Ok(()) => "the session ended".to_string(),
        Err(e) => format!("the session ended: {e:#}"),
    };
    shared.ended_tx.send_replace(Some(why));
    // Every client is told why before the server stops.
    let deadline = Instant::now() + Duration::from_secs(2);
    while shared.clients.load(std::sync::atomic::Ordering::SeqCst) > 0 && Instant::now() < deadline
    {
        std::thread::sleep(Duration::from_millis(5));
    }
    rt.shutdown_timeout(Duration::from_secs(2));
    result
}

/// The frame loop: renders while something changed or the cut has not
/// converged, sleeps otherwise.
fn frame_loop(
    opts: &ServeOptions,
    scene: &Scene,
    display: &Display,
    shared: &Shared,
    transport: &mut dyn Transport,
) -> Result<()> {
    let mut notes = Notes::default();
    let mut stats_file = match &opts.out {
        Some(dir) => Some(crate::stats_writer(dir, "stats.jsonl")?),
        None => None,
    };
    let mut rendered_version = 0u64;
    let mut since_change = 0u64;
    let mut converged = false;
    let mut sent_tf: Option<TransferFunction> = None;
    let mut tf_version = 1u64;
    let mut sent_tools = scene.tools.clone();
    let mut tools_version = 1u64;
    // What the back ends drew the layers with at set-up: the scene's files.
    let mut sent_layer_tfs = shared.live.lock().unwrap().state.layer_tfs.clone();
    let mut layer_tfs_version = 0u64;
    let mut recorder = match &opts.record {
        Some(dir) => Some(record::Recorder::start(
            dir.clone(),
            0,
            false,
            opts.record_limits,
        )?),
        None => None,
    };
    let mut page_recordings = 0u32;
    // Recordings whose script and movie are being written.
    let mut finishing = Vec::new();
    // While the page plays a series, when the next step is due.
    let mut next_tick: Option<Instant> = None;
    for frame in 0u64.. {
        let (state, version, pick, grow) = {
            let mut live = shared.live.lock().unwrap();
            loop {
                next_tick = play(shared, &mut live, next_tick);
                if live.quit
                    || live.version != rendered_version
                    || live.pick.is_some()
                    || !(converged || since_change >= SETTLE_FRAMES)
                {
                    break;
                }
                live = match next_tick {
                    Some(t) => {
                        let wait = t.saturating_duration_since(Instant::now());
                        shared.wake.wait_timeout(live, wait).unwrap().0
                    }
                    None => shared.wake.wait(live).unwrap(),
                };
            }
            if live.quit {
                break;
            }
            let pick = live.pick.take();
            let grow = if pick.is_some() {
                live.grow.take()
            } else {
                None
            };
            (live.state.clone(), live.version, pick, grow)
        };
        if version != rendered_version {
            since_change = 0;
        }
        // The page's record control.
        match (&recorder, state.recording) {
            (None, true) => {
                page_recordings += 1;
                match next_session_dir(&opts.record_dir, page_recordings)
                    .and_then(|dir| record::Recorder::start(dir, frame, true, opts.record_limits))
                {
                    Ok(r) => recorder = Some(r),
                    Err(e) => stop_recording(shared, &format!("record: {e:#}"))?,
                }
            }
            (Some(r), false) if r.started_by_page() => {
                finishing.push(finish(recorder.take().unwrap(), shared)?);
            }
            _ => {}
        }
        if sent_tf.as_ref() != Some(&state.tf) {
            if sent_tf.is_some() {
                tf_version += 1;
                transport.broadcast(&ToBackend::TransferFunction {
                    version: tf_version,
                    tf: state.tf.clone(),
                })?;
            }
            sent_tf = Some(state.tf.clone());
        }
        if state.layer_tfs != sent_layer_tfs {
            // The back ends read the scene's files at set-up; an edit
            // replaces them all.
            layer_tfs_version += 1;
            transport.broadcast(&ToBackend::LayerFunctions {
                version: layer_tfs_version,
                tfs: state.layer_tfs.iter().cloned().map(Some).collect(),
            })?;
            sent_layer_tfs = state.layer_tfs.clone();
        }
        if state.tools != sent_tools {
            tools_version += 1;
            transport.broadcast(&ToBackend::Tools {
                version: tools_version,
                tools: state.tools.clone(),
            })?;
            sent_tools = state.tools.clone();
        }
        let mut render = scene.render.clone();
        render.accuracy = state.accuracy;
        render.step_factor = state.step_factor;
        render.gamma = state.gamma;
        render.overlay.show = state.overlay;
        render.overlay.cursor = state.cursor;
        let fs = FrameState {
            frame,
            placement: state.placement,
            observer: display.observer.position,
            eta: state.eta,
            render,
            tf_version,
            tools_version,
            stream: state.streamed(display),
            pick,
            grow: grow.map(|(_, tolerance)| tolerance),
            layers: state.layers.clone(),
            step: state.time.step,
        };
        let start = Instant::now();
        transport.broadcast(&ToBackend::Frame(fs.clone()))?;
        let mut stats = transport.gather()?;
        let wall_ms = start.elapsed().as_secs_f64() * 1e3;
        if let Some(bad) = stats.iter().find(|s| s.error.is_some()) {
            anyhow::bail!(
                "back end {} failed: {}",
                bad.rank,
                bad.error.as_deref().unwrap_or("")
            );
        }
        crate::answers(&stats, fs.frame)?;
        if opts.present {
            crate::swap(transport, fs.frame, &mut stats)?;
        }
        notes.report(&stats);
        rendered_version = version;
        since_change += 1;
        converged = stats.iter().all(|s| s.adequate && s.uploaded == 0);
        let images: Vec<StreamImage> = stats
            .iter_mut()
            .flat_map(|s| std::mem::take(&mut s.images))
            .collect();
        let picked = stats.iter().find_map(|s| s.pick);
        let grown = stats.iter().find_map(|s| s.grown);
        if let Some(f) = stats_file.as_mut() {
            crate::write_stats(f, &stats)?;
        }
        let (w, h, rgb) = state.image(display, &images, opts.eye_view)?;
        let png = encode_png(w, h, &rgb)?;
        let step = recorder.as_mut().map(|r| r.frame(&fs, &state, &png));
        let recording = recorder.as_ref().map(|r| {
            let (frames, bytes) = r.progress();
            serde_json::json!({"frames": frames, "bytes": bytes})
        });
        match step {
            Some(Ok(record::Step::Full)) => {
                finishing.push(finish(recorder.take().unwrap(), shared)?);
                stop_recording(
                    shared,
                    &format!(
                        "record: the recording reached its bound ({} frames or {} MiB) and was stopped",
                        opts.record_limits.frames,
                        opts.record_limits.bytes >> 20
                    ),
                )?;
            }
            Some(Err(e)) => {
                recorder = None;
                stop_recording(shared, &format!("record: {e:#}; the recording is stopped"))?;
            }
            _ => {}
        }
        let header = serde_json::json!({
            "type": "frame",
            "frame": frame,
            "version": version,
            "width": w,
            "height": h,
            "wall_ms": wall_ms,
            "converged": converged,
            "coordinator_rss_bytes": parallax_common::resident_bytes(),
            "recording": recording,
            "stats": stats,
        });
        shared
            .frame_tx
            .send_replace(Some(Arc::new((header.to_string(), png))));
        match (pick.is_some(), grow) {
            (true, Some((index, _))) => grow_band(shared, index, grown),
            (true, None) => focus(shared, picked),
            _ => {}
        }
    }
    if let Some(r) = recorder.take() {
        finishing.push(r.finish(|done| match done {
            Ok(d) => println!("{}", d.summary()),
            Err(e) => eprintln!("warning: record: {e:#}"),
        })?);
    }
    for f in finishing {
        let _ = f.join();
    }
    if let Some(f) = stats_file {
        f.into_inner()
            .map_err(|e| anyhow::anyhow!("writing stats: {}", e.error()))?;
    }
    Ok(())
}

/// Finishes a recording off the frame loop; every page hears how it went.
fn finish(r: record::Recorder, shared: &Shared) -> Result<std::thread::JoinHandle<()>> {
    let tx = shared.notice_tx.clone();
    let page = r.started_by_page();
    r.finish(move |done| {
        let msg = match done {
            Ok(d) if page => d.message(),
            Ok(d) => {
                println!("{}", d.summary());
                return;
            }
            Err(e) => serde_json::json!({"type": "error", "message": format!("record: {e:#}")})
                .to_string(),
        };
        let _ = tx.send(msg);
    })
}

/// Ends a recording the loop could not go on with (a bound reached, a
/// disk that failed): the pages hear why, and the shared state says the
/// session is not recording, so the control does not start another.
fn stop_recording(shared: &Shared, why: &str) -> Result<()> {
    eprintln!("warning: {why}");
    shared.notice(why);
    shared.change(|s| {
        s.recording = false;
        Ok(())
    })
}

/// Moves the volume along z so the picked point lies on the screen plane,
/// where a light field display is sharpest (G10 §3: s(z) is smallest at
/// z = 0).
fn focus(shared: &Shared, picked: Option<[f64; 3]>) {
    let Some(p) = picked else {
        shared.notice("focus: nothing visible at that point");
        return;
    };
    // The change cannot fail: the centre is clamped to the state's limits.
    let _ = shared.change(|state| {
        let z = &mut state.placement.center[2];
        *z = (*z - p[2]).clamp(-state::CENTER_LIMIT, state::CENTER_LIMIT);
        Ok(())
    });
}

/// Sets band picker `index`'s band to the one grown from the clicked
/// point (G10 §4, region growing).
fn grow_band(shared: &Shared, index: usize, grown: Option<[f64; 4]>) {
    let Some(band) = grown else {
        shared.notice("grow-band: nothing visible at that point");
        return;
    };
    if let Err(e) = shared.change(|state| state.set_band(index, band)) {
        shared.notice(&format!("grow-band: {e:#}"));
    }
}

fn next_session_dir(root: &std::path::Path, n: u32) -> Result<PathBuf> {
    std::fs::create_dir_all(root).with_context(|| format!("{}: cannot create", root.display()))?;
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    Ok(root.join(format!("session-{stamp}-{n}")))
}

fn encode_png(w: u32, h: u32, rgb: &[u8]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut wr = enc.write_header()?;
    wr.write_image_data(rgb)?;
    wr.finish()?;
    Ok(out)
}

/// Pages connected at once, at most.
const MAX_CLIENTS: usize = 64;

/// The largest message a page may send (bytes).
const MAX_MESSAGE: usize = 1 << 20;

/// The shortest token taken: 22 letters and digits hold 62^22 > 2^128
/// choices.
const MIN_TOKEN: usize = 22;

fn random_token() -> Result<String> {
    use std::io::Read;
    let mut b = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut b))
        .context("/dev/urandom: cannot read a token")?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

#[derive(Clone)]
struct AppState {
    shared: Arc<Shared>,
    display: Arc<Display>,
}

fn authorised(app: &AppState, q: &HashMap<String, String>) -> bool {
    q.get("token")
        .is_some_and(|t| same(t.as_bytes(), app.shared.token.as_bytes()))
}

/// Equal, in a time that does not depend on where the two first differ
/// (a token guessed byte by byte learns nothing from the answer's time).
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// A browser's WebSocket from another site carries that site's `Origin`:
/// only the page this server served (same host and port) may open `/ws`.
/// Clients that are not browsers send no `Origin`.
fn same_origin(headers: &axum::http::HeaderMap) -> bool {
    let Some(origin) = headers.get(axum::http::header::ORIGIN) else {
        return true;
    };
    let host = headers
        .get(axum::http::header::HOST)
        .and_then(|h| h.to_str().ok());
    match (origin.to_str().ok(), host) {
        (Some(o), Some(h)) => o == format!("http://{h}") || o == format!("https://{h}"),
        _ => false,
    }
}

async fn page(State(app): State<AppState>, Query(q): Query<HashMap<String, String>>) -> Response {
    if !authorised(&app, &q) {
        return (
            StatusCode::FORBIDDEN,
            "parallax: open the URL printed at start (it carries the access token)",
        )
            .into_response();
    }
    Html(PAGE).into_response()
}

async fn ws_upgrade(
    State(app): State<AppState>,
    Query(q): Query<HashMap<String, String>>,
    headers: axum::http::HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    if !authorised(&app, &q) {
        return (StatusCode::FORBIDDEN, "parallax: wrong or missing token").into_response();
    }
    if !same_origin(&headers) {
        return (StatusCode::FORBIDDEN, "parallax: a page of another origin").into_response();
    }
    use std::sync::atomic::Ordering;
    if app.shared.clients.load(Ordering::SeqCst) >= MAX_CLIENTS {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("parallax: {MAX_CLIENTS} pages are connected already"),
        )
            .into_response();
    }
    // A message is a few hundred bytes (a transfer function of 256 points
    // a few kB): larger ones close the socket before they are read whole.
    ws.max_message_size(MAX_MESSAGE)
        .max_frame_size(MAX_MESSAGE)
        .on_upgrade(move |socket| client(socket, app))
}

/// One client: its messages change the shared state; it gets every state
/// change, the newest frame whenever there is one, and the notices.
async fn client(socket: WebSocket, app: AppState) {
    use std::sync::atomic::Ordering;
    /// Counts the client out however its task ends.
    struct Connected(Arc<Shared>);
    impl Drop for Connected {
        fn drop(&mut self) {
            self.0.clients.fetch_sub(1, Ordering::SeqCst);
        }
    }
    app.shared.clients.fetch_add(1, Ordering::SeqCst);
    let _connected = Connected(app.shared.clone());
    let shared = app.shared.clone();
    let (mut tx, mut rx) = socket.split();
    let mut state_rx = shared.state_tx.subscribe();
    let mut frame_rx = shared.frame_tx.subscribe();
    let mut ended_rx = shared.ended_tx.subscribe();
    let mut notice_rx = shared.notice_tx.subscribe();
    let state_now = state_rx.borrow_and_update().clone();
    let frame_now = frame_rx.borrow_and_update().clone();
    let mut outbox = vec![
        Message::Text(shared.hello.clone().into()),
        Message::Text(state_now.as_str().into()),
    ];
    if let Some(f) = frame_now {
        outbox.push(Message::Text(f.0.clone().into()));
        outbox.push(Message::Binary(f.1.clone().into()));
    }
    loop {
        for m in outbox.drain(..) {
            match tokio::time::timeout(SEND_TIMEOUT, tx.send(m)).await {
                Ok(Ok(())) => {}
                _ => return,
            }
        }
        tokio::select! {
            m = rx.next() => match m {
                Some(Ok(Message::Text(t))) => {
                    // The lock is held only for moments (the frame loop
                    // waits on the condition variable without it).
                    if let Err(e) = shared.apply(t.as_str(), &app.display) {
                        outbox.push(error_message(&e));
                    }
                }
                Some(Ok(Message::Binary(_))) => outbox.push(error_message("refused: binary messages are not part of the protocol")),
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => return,
                Some(Ok(_)) => {}
            },
            r = state_rx.changed() => {
                if r.is_err() { return; }
                let s = state_rx.borrow_and_update().clone();
                outbox.push(Message::Text(s.as_str().into()));
            }
            r = frame_rx.changed() => {
                if r.is_err() { return; }
                let f = frame_rx.borrow_and_update().clone();
                if let Some(f) = f {
                    outbox.push(Message::Text(f.0.clone().into()));
                    outbox.push(Message::Binary(f.1.clone().into()));
                }
            }
            n = notice_rx.recv() => match n {
                Ok(n) => outbox.push(Message::Text(n.into())),
                Err(broadcast::error::RecvError::Lagged(_)) => {}
                Err(_) => return,
            },
            _ = ended_rx.changed() => {
                let why = ended_rx.borrow().clone().unwrap_or_default();
                let m = serde_json::json!({"type": "ended", "message": why}).to_string();
                let _ = tokio::time::timeout(SEND_TIMEOUT, tx.send(Message::Text(m.into()))).await;
                let _ = tx.close().await;
                return;
            }
        }
    }
}

fn error_message(e: &str) -> Message {
    Message::Text(
        serde_json::json!({"type": "error", "message": e})
            .to_string()
            .into(),
    )
}
