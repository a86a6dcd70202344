//! `parallax serve`: the live control page driving the display.

use super::args;
use crate::launch;
use anyhow::Result;
use std::path::PathBuf;

/// Live: serve a control page and drive the display from a browser
/// (embedded, or from rank 0 under `mpirun`). Prints the page's URL,
/// with its access token.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    target: args::SceneDisplay,
    /// Address to listen on. The default is this machine only; another
    /// address exposes the page to the network (the token guards it).
    #[arg(long, default_value = "127.0.0.1:8080")]
    bind: std::net::SocketAddr,
    /// The access token: at least 22 letters and digits (128 bits; default:
    /// a random one, printed in the URL). Also read from PARALLAX_TOKEN,
    /// which, unlike the command line, other users cannot see in `ps`.
    #[arg(long, env = "PARALLAX_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Also write every frame's images and stats here, as `render` does.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Wait for every posted brick read before each frame (a recording
    /// then replays bit for bit).
    #[arg(long)]
    sync: bool,
    /// Record the whole session from its first frame into this folder
    /// (script.toml, written when the session ends).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Where the page's record control writes its sessions.
    #[arg(long, default_value = "out/live")]
    record_dir: PathBuf,
    /// A recording stops itself after this many frames.
    #[arg(long, default_value_t = parallax_frontend::live::record::Limits::default().frames)]
    record_max_frames: usize,
    /// … or after this many MiB of images.
    #[arg(long, default_value_t = parallax_frontend::live::record::Limits::default().bytes >> 20)]
    record_max_mb: u64,
    /// Show every frame on the display's outputs too, all back ends
    /// together (as `render --present`).
    #[arg(long)]
    present: bool,
    /// Embedded back-end threads (default: from the display).
    #[arg(long)]
    backends: Option<usize>,
    /// Seconds to wait for a back end's frame before naming it and
    /// ending the session (0: wait forever).
    #[arg(long, default_value_t = parallax_common::protocol::DEFAULT_WATCHDOG.as_secs_f64())]
    watchdog: f64,
}

pub fn run(a: Args) -> Result<()> {
    let opts = parallax_frontend::live::ServeOptions {
        scene: a.target.scene.clone(),
        display: a.target.display.clone(),
        bind: a.bind,
        token: a.token,
        out: a.out,
        sync_io: a.sync,
        record: a.record,
        record_dir: a.record_dir,
        record_limits: parallax_frontend::live::record::Limits {
            frames: a.record_max_frames.max(1),
            bytes: a.record_max_mb.max(1) << 20,
        },
        watchdog: args::watchdog(a.watchdog)?,
        ready: None,
        eye_view: launch::eye_view,
        present: a.present,
    };
    launch::session(
        &a.target.scene,
        a.target.display.as_ref(),
        a.backends,
        |t| parallax_frontend::live::serve(opts, t),
    )?;
    Ok(())
}
