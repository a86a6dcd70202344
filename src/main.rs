//! `parallax`: the command line (docs/design.md "Command line"). Each
//! command lives in its module of [`parallax::cmd`]; this file parses and
//! dispatches.

use clap::Parser;
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "parallax",
    version,
    about = "Massive volumes on light field displays and ordinary screens"
)]
struct Cli {
    #[command(subcommand)]
    command: parallax::cmd::Command,
}

fn main() {
    ensure_runtime_dir();
    parallax_backend::gpu::spread_cpu_device_work();
    init_logging();
    parallax_backend::data::install_hook();
    if let Err(e) = parallax::cmd::run(Cli::parse().command) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// The Vulkan stack wants a per-user runtime folder and prints an error line
/// on every start without one (a headless shell, a batch job, an MPI rank):
/// give it one, private to this user, before any GPU work.
fn ensure_runtime_dir() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let usable = std::env::var_os("XDG_RUNTIME_DIR")
        .map(PathBuf::from)
        .is_some_and(|p| p.is_absolute() && p.is_dir());
    if usable {
        return;
    }
    let uid = std::fs::metadata("/proc/self").map_or(0, |m| m.uid());
    let dir = std::env::temp_dir().join(format!("parallax-runtime-{uid}"));
    if std::fs::create_dir_all(&dir).is_ok()
        && std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).is_ok()
    {
        // Single-threaded here: nothing else reads the environment yet.
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

/// Diagnostics on standard error, chosen with `RUST_LOG` (default: warnings
/// and errors only): the adapter choice, wgpu's own messages, the loader's
/// decisions, MPI start-up. Per-frame figures go to `stats.jsonl`.
fn init_logging() {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

/// Decoders of untrusted files run with a cap on single allocations
/// (`parallax_backend::data::CappedAlloc`).
#[global_allocator]
static ALLOC: parallax_backend::data::CappedAlloc = parallax_backend::data::CappedAlloc;
