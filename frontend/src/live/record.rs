//! Recording a live session: every rendered frame's state becomes a key of
//! an interaction script that `parallax render --script` replays frame for
//! frame (a recording from the session's first frame, with `--sync` on
//! both sides, replays bit for bit: the cut is refined from the same
//! states in the same order), and the streamed images become a movie (MP4
//! through ffmpeg when it is installed, else an animated GIF).
//!
//! A recording never holds up the frame loop: the images are written by a
//! thread of their own (a queue of [`QUEUE`] frames; a frame the disk cannot
//! take in time is left out of the movie, and counted), the script and the
//! movie are written by another after the stop, at the lowest CPU priority.
//! It is bounded ([`Limits`], said on the page): at a
//! bound it stops itself as if the page had stopped it. A failure (a full
//! disk) stops the recording, not the session.

use super::LiveState;
use crate::script::{Key, LayerFunctionKey, PlacementKey, ScriptFile, ToolSet};
use anyhow::{Context, Result};
use parallax_common::protocol::FrameState;
use parallax_common::tf::TransferFunction;
use parallax_common::tools::Tool;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::thread::JoinHandle;

/// Where a recording stops itself (`serve --record-max-frames`,
/// `--record-max-mb`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Frames (the default: ten minutes at 30 frames a second).
    pub frames: usize,
    /// Bytes of images (the movie's frames; the default: 4 GiB).
    pub bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            frames: 18_000,
            bytes: 4 << 30,
        }
    }
}

impl Limits {
    /// As the page shows them (`record_limits` in `hello`).
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({"frames": self.frames, "bytes": self.bytes})
    }
}
/// Images waiting for the writer at most.
const QUEUE: usize = 32;

/// One recorded frame: what the script must reproduce.
#[derive(Clone, Debug, PartialEq)]
struct Recorded {
    state: FrameState,
    tf: TransferFunction,
    /// The layers' transfer functions (`[[layer]]` order).
    layer_tfs: Vec<TransferFunction>,
    tools: Vec<Tool>,
}

pub struct Recorder {
    dir: PathBuf,
    first: u64,
    /// Started from the page (a movie is written too, and the page's
    /// control stops it).
    page: bool,
    frames: Vec<Recorded>,
    limits: Limits,
    /// Bytes of images handed to the writer.
    bytes: u64,
    /// Images left out of the movie because the writer was behind.
    dropped: usize,
    images: Option<SyncSender<Vec<u8>>>,
    /// Writes `frames/00000.png`, …; returns how many it wrote.
    writer: Option<JoinHandle<Result<usize>>>,
}

/// Whether a recording goes on after a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    Recording,
    /// A bound is reached: the recording must be finished.
    Full,
}

/// What a finished recording wrote.
pub struct Done {
    pub script: PathBuf,
    pub movie: Option<PathBuf>,
    pub frames: usize,
    /// Frames whose image the disk could not take in time (in the script,
    /// not in the movie).
    pub dropped: usize,
}

impl Done {
    pub fn message(&self) -> String {
        serde_json::json!({
            "type": "recorded",
            "script": self.script.display().to_string(),
            "movie": self.movie.as_ref().map(|m| m.display().to_string()),
            "frames": self.frames,
            "dropped": self.dropped,
        })
        .to_string()
    }

    pub fn summary(&self) -> String {
        format!(
            "recorded {} frames: {}{}{}",
            self.frames,
            self.script.display(),
            self.movie
                .as_ref()
                .map(|m| format!(", {}", m.display()))
                .unwrap_or_default(),
            if self.dropped > 0 {
                format!(
                    " ({} images the disk could not take in time are not in the movie)",
                    self.dropped
                )
            } else {
                String::new()
            }
        )
    }
}

impl Recorder {
    pub fn start(dir: PathBuf, first: u64, page: bool, limits: Limits) -> Result<Self> {
        let frames_dir = dir.join("frames");
        std::fs::create_dir_all(&frames_dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        let (tx, rx) = sync_channel::<Vec<u8>>(QUEUE);
        let writer = std::thread::Builder::new()
            .name("parallax-record".into())
            .spawn(move || {
                lowest_priority();
                let mut n = 0;
                for png in rx {
                    let p = frames_dir.join(format!("{n:05}.png"));
                    std::fs::write(&p, png)
                        .with_context(|| format!("{}: cannot write", p.display()))?;
                    n += 1;
                }
                Ok(n)
            })
            .context("cannot start the recording's writer")?;
        Ok(Recorder {
            dir,
            first,
            page,
            frames: Vec::new(),
            limits,
            bytes: 0,
            dropped: 0,
            images: Some(tx),
            writer: Some(writer),
        })
    }

    pub fn started_by_page(&self) -> bool {
        self.page
    }

    /// Frames and image bytes so far.
    pub fn progress(&self) -> (usize, u64) {
        (self.frames.len(), self.bytes)
    }

    /// Records one rendered frame and hands its streamed image (PNG) to
    /// the writer. An error is the writer's (the disk's): the recording is
    /// over, the session goes on.
    pub fn frame(&mut self, fs: &FrameState, live: &LiveState, png: &[u8]) -> Result<Step> {
        let mut state = fs.clone();
        state.frame -= self.first;
        self.frames.push(Recorded {
            state,
            tf: live.tf.clone(),
            layer_tfs: live.layer_tfs.clone(),
            tools: live.tools.clone(),
        });
        self.bytes += png.len() as u64;
        if let Some(tx) = &self.images {
            match tx.try_send(png.to_vec()) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => self.dropped += 1,
                Err(TrySendError::Disconnected(_)) => {
                    self.images = None;
                    return match self.writer.take().map(JoinHandle::join) {
                        Some(Ok(Err(e))) => Err(e),
                        _ => Err(anyhow::anyhow!("the recording's writer stopped")),
                    };
                }
            }
        }
        Ok(
            if self.frames.len() >= self.limits.frames || self.bytes >= self.limits.bytes {
                Step::Full
            } else {
                Step::Recording
            },
        )
    }

    /// Writes the script and (for a page's recording) the movie, once the
    /// writer has written every queued image: on a thread of its own at the
    /// lowest CPU priority, so the frame loop goes on at its pace; `done`
    /// gets the outcome there.
    pub fn finish(
        mut self,
        done: impl FnOnce(Result<Done>) + Send + 'static,
    ) -> Result<JoinHandle<()>> {
        std::thread::Builder::new()
            .name("parallax-movie".into())
            .spawn(move || {
                lowest_priority();
                done(self.write());
            })
            .context("cannot start the recording's encoder")
    }

    fn write(&mut self) -> Result<Done> {
        self.images = None;
        let written = match self.writer.take().map(JoinHandle::join) {
            Some(Ok(r)) => r?,
            Some(Err(_)) => anyhow::bail!("the recording's writer panicked"),
            None => 0,
        };
        let script = self.dir.join("script.toml");
        let file = script_of(&self.frames, &self.dir)?;
        file.write(&script)?;
        let movie = if self.page && written > 0 {
            Some(write_movie(&self.dir)?)
        } else {
            None
        };
        Ok(Done {
            script,
            movie,
            frames: self.frames.len(),
            dropped: self.dropped,
        })
    }
}

/// Lowers the calling thread's CPU priority to the lowest (nice 19; the
/// ffmpeg it starts inherits it): a recording's disk and encoding work
/// yields to the frame loop and the renderers.
fn lowest_priority() {
    // SAFETY: setpriority on the calling thread's own id has no memory
    // effects; a failure leaves the priority as it was.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, 19);
    }
}

/// The whole state of a frame as one key (every later value interpolates
/// from equal keys, or switches between adjacent frames: exact).
fn key_of(r: &Recorded, tf_file: Option<PathBuf>, layer_functions: Vec<LayerFunctionKey>) -> Key {
    let s = &r.state;
    Key {
        frame: s.frame,
        placement: PlacementKey {
            center: Some(s.placement.center),
            rotation_deg: Some(s.placement.rotation_deg),
            size: Some(s.placement.size),
        },
        observer: Some(s.observer),
        eta: Some(s.eta),
        gamma: Some(s.render.gamma),
        accuracy: Some(s.render.accuracy),
        step_factor: Some(s.render.step_factor),
        time: Some(s.step as f64),
        transfer_function: tf_file,
        // The whole tool set: a page may have added or removed tools.
        tool: Vec::new(),
        tools: Some(ToolSet(r.tools.clone())),
        cursor: s.render.overlay.cursor,
        overlay: Some(s.render.overlay.show),
        layers: (!s.layers.is_empty()).then(|| s.layers.clone()),
        layer_functions,
    }
}

/// Keys where the state changes, each preceded by a key holding the old
/// state on the frame before (linear interpolation between equal keys is
/// exact, so every frame replays as recorded). Transfer functions are
/// written beside the script, one file per change.
fn script_of(frames: &[Recorded], dir: &Path) -> Result<ScriptFile> {
    let mut keys: Vec<Key> = Vec::new();
    let mut tfs = 0;
    let same = |a: &Recorded, b: &Recorded| {
        let mut sa = a.state.clone();
        sa.frame = b.state.frame;
        sa.tf_version = b.state.tf_version;
        sa.tools_version = b.state.tools_version;
        sa.stream.clone_from(&b.state.stream);
        sa.pick = b.state.pick;
        sa == b.state && a.tf == b.tf && a.layer_tfs == b.layer_tfs && a.tools == b.tools
    };
    let mut write_tf = |tf: &TransferFunction| -> Result<PathBuf> {
        tfs += 1;
        let name = format!("tf-{tfs:03}.toml");
        let text = toml::to_string(tf).context("cannot write a transfer function")?;
        parallax_common::atomic::write(&dir.join(&name), text.as_bytes())?;
        Ok(PathBuf::from(name))
    };
    for (i, r) in frames.iter().enumerate() {
        let changed = i == 0 || !same(&frames[i - 1], r);
        if !changed {
            continue;
        }
        if i > 0 && keys.last().is_some_and(|k| k.frame + 1 < r.state.frame) {
            keys.push(key_of(&frames[i - 1], None, Vec::new()));
        }
        let tf_file = if i == 0 || frames[i - 1].tf != r.tf {
            Some(write_tf(&r.tf)?)
        } else {
            None
        };
        // Each layer's function where the page changed it.
        let mut layer_functions = Vec::new();
        for (index, tf) in r.layer_tfs.iter().enumerate() {
            if i == 0 || frames[i - 1].layer_tfs.get(index) != Some(tf) {
                layer_functions.push(LayerFunctionKey {
                    index,
                    file: write_tf(tf)?,
                });
            }
        }
        keys.push(key_of(r, tf_file, layer_functions));
    }
    Ok(ScriptFile {
        frames: Some(frames.len() as u64),
        key: keys,
    })
}

/// The recorded frames as a movie: MP4 through ffmpeg when it is on the
/// PATH, else an animated GIF (frames of another size than the first, after
/// the output was switched, are left out of the GIF).
fn write_movie(dir: &Path) -> Result<PathBuf> {
    let frames = dir.join("frames");
    let mp4 = dir.join("movie.mp4");
    let ffmpeg = std::process::Command::new("ffmpeg")
        .args(["-loglevel", "error", "-y", "-framerate", "30", "-i"])
        .arg(frames.join("%05d.png"))
        .args([
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
            "-pix_fmt",
            "yuv420p",
        ])
        .arg(&mp4)
        .status();
    if ffmpeg.is_ok_and(|s| s.success()) {
        return Ok(mp4);
    }
    let gif_path = dir.join("movie.gif");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&frames)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    names.sort();
    let Some(first) = names.first() else {
        anyhow::bail!("{}: no frames to make a movie of", frames.display());
    };
    let (w, h, _) = read_png_rgb(first)?;
    let mut file = parallax_common::atomic::AtomicFile::create(&gif_path)?;
    {
        let mut enc = gif::Encoder::new(&mut file, w as u16, h as u16, &[])?;
        enc.set_repeat(gif::Repeat::Infinite)?;
        for p in &names {
            let (fw, fh, rgb) = read_png_rgb(p)?;
            if [fw, fh] != [w, h] {
                continue;
            }
            let mut f = gif::Frame::from_rgb_speed(w as u16, h as u16, &rgb, 10);
            f.delay = 3; // 1/100 s: about 30 frames per second
            enc.write_frame(&f)?;
        }
    }
    file.commit()?;
    Ok(gif_path)
}

fn read_png_rgb(p: &Path) -> Result<(u32, u32, Vec<u8>)> {
    let f = std::fs::File::open(p).with_context(|| format!("{}: cannot read", p.display()))?;
    let mut reader = png::Decoder::new(std::io::BufReader::new(f)).read_info()?;
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf)?;
    buf.truncate(info.buffer_size());
    anyhow::ensure!(
        info.color_type == png::ColorType::Rgb,
        "{}: not an RGB frame",
        p.display()
    );
    Ok((info.width, info.height, buf))
}
