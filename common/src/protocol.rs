//! What the front end and the back ends say to each other (docs/design.md
//! "Process model"): small per-frame state broadcast to every back end, a
//! stats reply from each, and the large state (scene, display, transfer
//! function) sent once and again only when it changes. Messages travel as
//! bincode bytes over a [`Transport`]: an in-process channel, or MPI.

use crate::camera::Placement;
use crate::config::{Display, RenderConfig, Scene};
use crate::tf::TransferFunction;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// How long the front end waits for every back end's reply to a frame before
/// it names the ranks that did not answer and ends the run (a stopped or
/// hung process must not hang the wall). Long enough for the first frame of
/// a large wall on a software rasteriser.
pub const DEFAULT_WATCHDOG: Duration = Duration::from_secs(120);

/// The per-frame state every back end renders frame `frame` from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameState {
    pub frame: u64,
    pub placement: Placement,
    pub observer: [f64; 3],
    pub eta: f64,
    pub render: RenderConfig,
    /// Which transfer function (sent earlier) to use.
    pub tf_version: u64,
    /// Which tool set (sent earlier) to use.
    #[serde(default)]
    pub tools_version: u64,
    /// The projectors (indices into the display's list) whose images the
    /// back ends send back with their stats: what the live coordinator
    /// streams. Empty outside `parallax serve`.
    #[serde(default)]
    pub stream: Vec<u32>,
    /// A focus click: a display-space ray (origin, unit direction) that the
    /// first back end marches through the volume (`FrameStats::pick`).
    #[serde(default)]
    pub pick: Option<[[f64; 3]; 2]>,
    /// With `pick`: grow a band picker's band from the picked point
    /// instead, within this fraction of the transfer function's value span
    /// (`FrameStats::grown`).
    #[serde(default)]
    pub grow: Option<f64>,
    /// The scene's registered layers as the live page or a script set
    /// them, in `[[layer]]` order; empty: as the scene file says.
    #[serde(default)]
    pub layers: Vec<LayerControl>,
    /// The time step of the scene's `series` drawn (0 without one).
    #[serde(default)]
    pub step: u32,
}

/// What the live page and scripts change of a registered layer
/// (`[[layer]]`): whether it is drawn, and its opacity in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayerControl {
    pub visible: bool,
    pub opacity: f64,
}

impl From<&crate::config::Layer> for LayerControl {
    fn from(l: &crate::config::Layer) -> Self {
        LayerControl {
            visible: l.visible,
            opacity: l.opacity,
        }
    }
}

/// One streamed projector image: sRGB 8-bit RGB rows, top row first, the
/// premultiplied colour over black (exactly what the PNG files hold).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamImage {
    /// Index into the display's projectors.
    pub projector: u32,
    pub width: u32,
    pub height: u32,
    pub rgb8: Vec<u8>,
}

/// Large state, sent once and again only when it changes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ToBackend {
    /// Every back end answers with a [`FrameStats`] holding its [`Ready`]
    /// (or its error).
    Setup {
        scene: Scene,
        display: Display,
        /// Where to write images and the float output flag.
        #[serde(with = "crate::paths::opt_bytes")]
        out_dir: Option<std::path::PathBuf>,
        float: bool,
        /// Wait for every posted brick read before refining a frame, so
        /// that a frame depends only on the frames before it (tests and
        /// comparisons between runs); interactive use never waits.
        sync_io: bool,
        /// Open the display's windows (`display.present`) and show every
        /// frame on them when told to ([`ToBackend::Present`]).
        present: bool,
    },
    TransferFunction {
        version: u64,
        tf: TransferFunction,
    },
    /// The tools (each an enhancer of the ray caster), sent when they
    /// change.
    Tools {
        version: u64,
        tools: Vec<crate::tools::Tool>,
    },
    Frame(FrameState),
    /// Swap lock: every back end has rendered this frame (the coordinator
    /// has all their stats); show it now. Each back end answers with a
    /// [`FrameStats`] that holds only its present figures.
    Present {
        frame: u64,
    },
    Quit,
    /// The registered layers' transfer functions, in `[[layer]]` order,
    /// as the live page edited them (`None`: the scene's file). Last, so
    /// that the other messages keep their encoding.
    LayerFunctions {
        version: u64,
        tfs: Vec<Option<TransferFunction>>,
    },
}

/// The version of these messages: a rank that speaks another is named
/// before the first frame.
pub const PROTOCOL_VERSION: u32 = 4;

/// This build: the workspace's version and the commit it was built from.
pub const BUILD: &str = concat!(env!("CARGO_PKG_VERSION"), " ", env!("PARALLAX_BUILD"));

/// A back end's answer to `Setup`: what it runs and what it renders, for
/// the coordinator to check that every rank agrees.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Ready {
    pub protocol: u32,
    pub build: String,
    /// The database's identity (header and node-table checksums).
    pub database: u64,
}

/// What a back end reports after each frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameStats {
    pub rank: u32,
    pub frame: u64,
    pub views: u32,
    /// Stage times, milliseconds.
    pub refine_ms: f64,
    pub upload_ms: f64,
    pub index_ms: f64,
    pub render_ms: f64,
    /// Frame reconstruction's filter (G10 §5) where it runs on the CPU;
    /// zero without it, and on the GPU, where it is part of `render_ms`.
    pub reconstruct_ms: f64,
    /// Writing the images (PNG, .npy) and the streamed copies.
    pub output_ms: f64,
    pub total_ms: f64,
    /// Bricks: nodes in the cut, leaves with data, resident in the GPU pool,
    /// uploaded this frame, marked visible by the last feedback.
    pub cut_nodes: u64,
    pub cut_leaves_with_data: u64,
    pub resident: u64,
    pub uploaded: u64,
    pub visible: u64,
    pub requested: u64,
    /// A series: reads the next step's loader posted this frame, reading
    /// ahead what this step draws.
    #[serde(default)]
    pub prefetched: u64,
    pub cache_hits: u64,
    pub cache_misses: u64,
    /// Bytes read from the database so far.
    pub bytes_read: u64,
    /// Bytes of decoded bricks in the CPU (L2) cache after this frame's
    /// refinement.
    #[serde(default)]
    pub cpu_bytes: u64,
    /// Every leaf of the cut is adequate (the image has converged).
    pub adequate: bool,
    /// An error that ended this back end, if any.
    pub error: Option<String>,
    /// Why refinement stopped short of adequate this frame, where the user
    /// can change it (a [`HeldBack`] each, named by its config field).
    #[serde(default)]
    pub held_back: Vec<HeldBack>,
    /// Bricks that failed to read or decode this frame (node and file
    /// offset): their parents stay leaves and the run goes on.
    #[serde(default)]
    pub bad_bricks: Vec<String>,
    /// Samples the kernel took this frame (counted only when asked for:
    /// benches and tests; else 0).
    #[serde(default)]
    pub samples: u64,
    /// 8×8 pixel tiles the ray-casting dispatch ran: those whose rays can
    /// meet data (the rest of the views' tiles are left out).
    #[serde(default)]
    pub tiles: u64,
    /// Of `render_ms`, the time the CPU took to list those tiles.
    #[serde(default)]
    pub tiles_ms: f64,
    /// Resident memory of this back end's process after the frame (bytes;
    /// in the embedded mode the whole process).
    #[serde(default)]
    pub rss_bytes: u64,
    /// The images of `FrameState::stream` this back end renders (the front
    /// end takes them out before writing `stats.jsonl`).
    #[serde(default)]
    pub images: Vec<StreamImage>,
    /// The answer to `FrameState::pick`: the display-space point where the
    /// ray's opacity reaches ½, if any (first back end only).
    #[serde(default)]
    pub pick: Option<[f64; 3]>,
    /// The answer to `FrameState::grow`: the band grown from the picked
    /// point, if the ray picked one (first back end only).
    #[serde(default)]
    pub grown: Option<[f64; 4]>,
    /// With `--present`: when this back end's windows were handed the frame
    /// (microseconds since the Unix epoch; the spread across ranks is the
    /// swap lock's), and how long converting and handing them took (ms).
    #[serde(default)]
    pub present_us: u64,
    #[serde(default)]
    pub present_ms: f64,
    /// Whether the windows were drawn straight from the renderer's image
    /// buffer on the device (no read-back), rather than from the images
    /// read back (as a calibration or a Looking Glass panel needs).
    #[serde(default)]
    pub present_direct: bool,
    /// The answer to `Setup` (only then).
    #[serde(default)]
    pub ready: Option<Ready>,
}

/// A limit that stopped refinement short of adequate, which the user can
/// raise (docs/design.md "Working set": refinement stops when the pool is full).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HeldBack {
    /// The spatial index addresses at most 65,535 nodes.
    IndexNodes,
    /// Every GPU pool slot holds a brick of the current cut.
    GpuPool,
    /// This frame's uploads were spent (`render.upload_budget`); the rest
    /// follow in the next frames.
    UploadBudget,
}

impl HeldBack {
    /// What to tell the user, once.
    pub fn advice(self) -> &'static str {
        match self {
            HeldBack::IndexNodes => "the spatial index is full (65,535 nodes): raise render.accuracy or use larger bricks (import --brick)",
            HeldBack::GpuPool => "the GPU brick pool is full: raise render.gpu_cache_mb or render.accuracy",
            HeldBack::UploadBudget => "the per-frame upload budget is spent: the cut refines over several frames (render.upload_budget)",
        }
    }
}

/// The bincode configuration of every message.
pub fn config() -> impl bincode::config::Config {
    bincode::config::standard()
}

/// Encodes a message. Fails (rather than panics) on anything bincode cannot
/// encode, so a strange input ends a run with a message, never a hang.
pub fn encode<T: Serialize>(msg: &T) -> Result<Vec<u8>> {
    bincode::serde::encode_to_vec(msg, config()).context("cannot encode a protocol message")
}

/// A message that does not decode: the receiver answers with an error
/// instead of waiting for more.
#[derive(Debug)]
pub struct Malformed(pub String);

impl std::fmt::Display for Malformed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "malformed protocol message: {}", self.0)
    }
}

impl std::error::Error for Malformed {}

/// The most a message's decoding may claim (bytes of strings, vectors):
/// a length that a crafted or corrupt message declares is refused here,
/// before it is allocated.
pub const MAX_MESSAGE_BYTES: usize = 1 << 30;

pub fn decode<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T> {
    let (v, _) = bincode::serde::decode_from_slice(
        bytes,
        // config(), with the limit.
        bincode::config::standard().with_limit::<MAX_MESSAGE_BYTES>(),
    )
    .map_err(|e| Malformed(e.to_string()))?;
    Ok(v)
}

/// The front end's side: broadcast to all back ends, gather their replies.
pub trait Transport {
    /// Number of back ends.
    fn backends(&self) -> usize;
    fn broadcast(&mut self, msg: &ToBackend) -> Result<()>;
    /// One reply from every back end (swap lock: returns once all finished),
    /// or an error naming the back ends that did not reply within the
    /// watchdog timeout.
    fn gather(&mut self) -> Result<Vec<FrameStats>>;
    /// The watchdog timeout of [`Transport::gather`] (`None`: wait forever).
    fn set_watchdog(&mut self, timeout: Option<Duration>);
}

/// The error of a gather whose deadline passed: the back ends that did not
/// answer. A launcher must end those processes itself (they cannot be told
/// to quit): see `parallax_frontend::cluster::abort_job`.
#[derive(Debug)]
pub struct Unresponsive {
    pub ranks: Vec<u32>,
    pub timeout: Duration,
}

impl std::fmt::Display for Unresponsive {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ranks: Vec<String> = self.ranks.iter().map(|r| r.to_string()).collect();
        write!(
            f,
            "back end rank{} {} did not answer within {:.0} s (stopped or hung; watchdog timeout, --watchdog)",
            if self.ranks.len() > 1 { "s" } else { "" },
            ranks.join(", "),
            self.timeout.as_secs_f64()
        )
    }
}

impl std::error::Error for Unresponsive {}

pub fn watchdog_error(missing: &[u32], timeout: Duration) -> anyhow::Error {
    Unresponsive {
        ranks: missing.to_vec(),
        timeout,
    }
    .into()
}

/// A back end's side.
pub trait Link {
    fn rank(&self) -> u32;
    fn receive(&mut self) -> Result<ToBackend>;
    fn reply(&mut self, stats: &FrameStats) -> Result<()>;
}

/// In-process transport: the embedded mode runs the back ends as threads and
/// passes the same bincode bytes over channels.
pub struct ChannelTransport {
    to: Vec<mpsc::Sender<Vec<u8>>>,
    from: mpsc::Receiver<Vec<u8>>,
    watchdog: Option<Duration>,
}

pub struct ChannelLink {
    rank: u32,
    from: mpsc::Receiver<Vec<u8>>,
    to: mpsc::Sender<Vec<u8>>,
}

/// A front-end transport and `n` back-end links (ranks 1..=n).
pub fn channels(n: usize) -> (ChannelTransport, Vec<ChannelLink>) {
    let (reply_tx, reply_rx) = mpsc::channel();
    let mut to = Vec::new();
    let mut links = Vec::new();
    for r in 0..n {
        let (tx, rx) = mpsc::channel();
        to.push(tx);
        links.push(ChannelLink {
            rank: r as u32 + 1,
            from: rx,
            to: reply_tx.clone(),
        });
    }
    (
        ChannelTransport {
            to,
            from: reply_rx,
            watchdog: Some(DEFAULT_WATCHDOG),
        },
        links,
    )
}

impl Transport for ChannelTransport {
    fn backends(&self) -> usize {
        self.to.len()
    }

    fn broadcast(&mut self, msg: &ToBackend) -> Result<()> {
        let bytes = encode(msg)?;
        for (i, t) in self.to.iter().enumerate() {
            t.send(bytes.clone())
                .map_err(|_| anyhow::anyhow!("back end {} has stopped", i + 1))?;
        }
        Ok(())
    }

    fn gather(&mut self) -> Result<Vec<FrameStats>> {
        let n = self.to.len();
        let deadline = self.watchdog.map(|t| Instant::now() + t);
        let mut out: Vec<FrameStats> = Vec::with_capacity(n);
        while out.len() < n {
            let bytes = match deadline {
                None => self
                    .from
                    .recv()
                    .map_err(|_| mpsc::RecvTimeoutError::Disconnected),
                Some(d) => self
                    .from
                    .recv_timeout(d.saturating_duration_since(Instant::now())),
            };
            match bytes {
                Ok(b) => out.push(decode::<FrameStats>(&b)?),
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    anyhow::bail!("a back end stopped without replying")
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let missing: Vec<u32> = (1..=n as u32)
                        .filter(|r| !out.iter().any(|s| s.rank == *r))
                        .collect();
                    return Err(watchdog_error(&missing, self.watchdog.unwrap_or_default()));
                }
            }
        }
        out.sort_by_key(|s| s.rank);
        Ok(out)
    }

    fn set_watchdog(&mut self, timeout: Option<Duration>) {
        self.watchdog = timeout;
    }
}

impl Link for ChannelLink {
    fn rank(&self) -> u32 {
        self.rank
    }

    fn receive(&mut self) -> Result<ToBackend> {
        let bytes = self
            .from
            .recv()
            .map_err(|_| anyhow::anyhow!("the front end has stopped"))?;
        decode(&bytes)
    }

    fn reply(&mut self, stats: &FrameStats) -> Result<()> {
        self.to
            .send(encode(stats)?)
            .map_err(|_| anyhow::anyhow!("the front end has stopped"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_state_round_trips_and_is_small() {
        let s = FrameState {
            frame: 12,
            placement: Placement {
                center: [0.0, 0.1, 0.0],
                rotation_deg: [0.0, 45.0, 0.0],
                size: 0.3,
            },
            observer: [0.0, 0.0, 2.0],
            eta: 1.0,
            render: RenderConfig::default(),
            tf_version: 1,
            tools_version: 1,
            stream: Vec::new(),
            pick: None,
            grow: None,
            layers: Vec::new(),
            step: 0,
        };
        let msg = ToBackend::Frame(s.clone());
        let b = encode(&msg).unwrap();
        assert!(b.len() < 256, "{} bytes", b.len());
        assert_eq!(decode::<ToBackend>(&b).unwrap(), msg);
        assert!(decode::<ToBackend>(&b[..b.len() / 2]).is_err());
    }

    #[test]
    fn setup_messages_round_trip() {
        // Everything sent once (scene, display, transfer function) goes
        // through bincode too: no serde features it cannot encode.
        let dir = std::env::temp_dir().join(format!("px-proto-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("p")).unwrap();
        std::fs::write(
            dir.join("d.toml"),
            "[screen]\nsize = [0.4, 0.3]\npixel_size = 0.001\n[observer]\nposition = [0, 0, 1]\nprojectors = \"p/\"\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("p/a.toml"),
            "id = \"a\"\nposition = [0, 0, 1]\nresolution = [8, 8]\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("s.toml"),
            "volume = \"v.pxo\"\ntransfer_function = \"t.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n",
        )
        .unwrap();
        let setup = ToBackend::Setup {
            scene: Scene::load(&dir.join("s.toml")).unwrap(),
            display: Display::load(&dir.join("d.toml")).unwrap(),
            out_dir: Some(dir.clone()),
            float: true,
            sync_io: false,
            present: true,
        };
        assert_eq!(
            decode::<ToBackend>(&encode(&setup).unwrap()).unwrap(),
            setup
        );
        let tf = TransferFunction::from_toml_str(
            "[[point]]\nvalue = 0\ncolor = [1, 0, 0]\nextinction = 0.5\n",
            "t.toml",
        )
        .unwrap();
        let m = ToBackend::TransferFunction { version: 3, tf };
        assert_eq!(decode::<ToBackend>(&encode(&m).unwrap()).unwrap(), m);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn channels_broadcast_and_gather() {
        let (mut t, links) = channels(3);
        let handles: Vec<_> = links
            .into_iter()
            .map(|mut l| {
                std::thread::spawn(move || {
                    while let Ok(m) = l.receive() {
                        match m {
                            ToBackend::Quit => break,
                            ToBackend::Frame(f) => l
                                .reply(&FrameStats {
                                    rank: l.rank(),
                                    frame: f.frame,
                                    ..Default::default()
                                })
                                .unwrap(),
                            _ => {}
                        }
                    }
                })
            })
            .collect();
        let f = FrameState {
            frame: 7,
            placement: Placement {
                center: [0.0; 3],
                rotation_deg: [0.0; 3],
                size: 1.0,
            },
            observer: [0.0, 0.0, 1.0],
            eta: 0.0,
            render: RenderConfig::default(),
            tf_version: 0,
            tools_version: 0,
            stream: Vec::new(),
            pick: None,
            grow: None,
            layers: Vec::new(),
            step: 0,
        };
        t.broadcast(&ToBackend::Frame(f)).unwrap();
        let stats = t.gather().unwrap();
        assert_eq!(
            stats.iter().map(|s| (s.rank, s.frame)).collect::<Vec<_>>(),
            vec![(1, 7), (2, 7), (3, 7)]
        );
        t.broadcast(&ToBackend::Quit).unwrap();
        for h in handles {
            h.join().unwrap();
        }
    }

    #[test]
    fn gather_names_the_back_end_that_does_not_answer() {
        let (mut t, mut links) = channels(3);
        t.set_watchdog(Some(Duration::from_millis(200)));
        // Back ends 1 and 3 answer; back end 2 is alive but silent.
        for l in links.iter_mut().filter(|l| l.rank() != 2) {
            let rank = l.rank();
            l.reply(&FrameStats {
                rank,
                ..Default::default()
            })
            .unwrap();
        }
        let start = Instant::now();
        let e = t.gather().unwrap_err().to_string();
        assert!(start.elapsed() < Duration::from_secs(5));
        assert!(e.contains("rank 2 ") && e.contains("did not answer"), "{e}");
    }
}
