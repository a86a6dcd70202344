//! Starting a session (docs/design.md "Process model"). Under `mpirun -n K`,
//! rank 0 coordinates and ranks 1…K−1 render; otherwise (or with one MPI
//! process) the back ends are threads of this process and talk to the
//! coordinator through the same protocol. Both `render` and `serve` start
//! here: the coordinator is a closure over a [`Transport`].

use anyhow::{bail, Context, Result};
use parallax_common::config::{Display, Scene};
use parallax_common::protocol::{StreamImage, Transport, Unresponsive};
use std::path::{Path, PathBuf};

/// Which part of the session this process played.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Coordinator,
    Backend,
}

/// Runs a session: `coordinate` on the coordinator with a transport to
/// every back end. `backends` sets the number of embedded back-end threads
/// (default: [`display_ranks`] of `scene`/`display`); under MPI the launcher
/// sets it.
pub fn session(
    scene: &Path,
    display: Option<&PathBuf>,
    backends: Option<usize>,
    coordinate: impl FnOnce(&mut dyn Transport) -> Result<()>,
) -> Result<Role> {
    let launched = parallax_frontend::cluster::launched_by_mpi();
    match plan(launched, backends, || display_ranks(scene, display))? {
        Plan::Mpi => mpi_session(coordinate),
        Plan::Embedded { backends } => {
            embedded(backends, coordinate)?;
            Ok(Role::Coordinator)
        }
    }
}

/// How a session runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan {
    /// Under `mpirun`: rank 0 coordinates, the other ranks render (one
    /// MPI process alone falls back to one embedded back end).
    Mpi,
    /// Back-end threads of this process.
    Embedded { backends: usize },
}

/// The plan of a session: MPI when `mpirun` started this process (the
/// launcher then sets the ranks and `--backends` is not used), otherwise
/// `backends` embedded back ends, by default the `display_ranks` the
/// display asks for (read only when needed).
pub fn plan(
    launched_by_mpi: bool,
    backends: Option<usize>,
    display_ranks: impl FnOnce() -> Result<usize>,
) -> Result<Plan> {
    if launched_by_mpi {
        return Ok(Plan::Mpi);
    }
    let backends = match backends {
        Some(n) => n,
        None => display_ranks()?,
    };
    if backends == 0 {
        bail!("--backends 0: at least one back end is needed");
    }
    Ok(Plan::Embedded { backends })
}

/// The cluster mode, under `mpirun -n K` (one MPI process alone runs the
/// embedded mode).
fn mpi_session(coordinate: impl FnOnce(&mut dyn Transport) -> Result<()>) -> Result<Role> {
    use mpi::traits::Communicator;
    let universe = mpi::initialize().context("MPI initialisation failed")?;
    let world = universe.world();
    let (rank, size) = (world.rank(), world.size() as usize);
    tracing::info!(
        rank,
        ranks = size,
        host = %std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default().trim(),
        "MPI started: {}",
        if rank == 0 { "coordinator" } else { "back end" }
    );
    if size < 2 {
        drop(universe);
        embedded(1, coordinate)?;
        return Ok(Role::Coordinator);
    }
    // A panic that no back end catches (the coordinator's, an I/O thread's)
    // must not leave the other ranks waiting for a message that never comes.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        default_hook(info);
        if !parallax_backend::node::catching_panics() {
            eprintln!("error: rank {rank} panicked; ending the MPI job");
            parallax_frontend::cluster::abort_job(101);
        }
    }));
    if rank == 0 {
        let mut t = parallax_frontend::cluster::transport(world);
        match coordinate(&mut t) {
            Ok(()) => Ok(Role::Coordinator),
            // Ranks that stopped answering cannot be told to quit: end the
            // job so the launcher kills them.
            Err(e) if e.is::<Unresponsive>() => {
                eprintln!("error: {e:#}");
                parallax_frontend::cluster::abort_job(1)
            }
            Err(e) => Err(e),
        }
    } else {
        let mut link = parallax_frontend::cluster::link(world);
        // A back end's error has been reported to rank 0, which exits
        // non-zero naming it; the back end itself ends quietly.
        if let Err(e) = parallax_backend::node::serve(&mut link, size - 1) {
            eprintln!("rank {rank}: {e:#}");
        }
        Ok(Role::Backend)
    }
}

/// The back ends a display asks for: the highest rank its projector files
/// name, or 1 when none names one.
pub fn display_ranks(scene: &Path, display: Option<&PathBuf>) -> Result<usize> {
    let scene = Scene::load(scene)?;
    let display = parallax_frontend::load_display(&scene, display)?;
    Ok(display
        .projectors
        .iter()
        .filter_map(|p| p.rank)
        .max()
        .map_or(1, |r| r as usize))
}

/// The embedded mode: the coordinator on this thread, `backends` back ends
/// on threads of their own, talking through the same protocol as over MPI.
pub fn embedded(
    backends: usize,
    coordinate: impl FnOnce(&mut dyn Transport) -> Result<()>,
) -> Result<()> {
    if backends == 0 {
        bail!("--backends 0: at least one back end is needed");
    }
    let (mut transport, links) = parallax_common::protocol::channels(backends);
    let threads: Vec<_> = links
        .into_iter()
        .map(|mut link| {
            std::thread::spawn(move || parallax_backend::node::serve(&mut link, backends))
        })
        .collect();
    let result = coordinate(&mut transport);
    drop(transport);
    if let Err(e) = &result {
        if e.is::<Unresponsive>() {
            // A back end thread that does not answer cannot be joined; the
            // process ends with the error and takes it along.
            return result;
        }
    }
    let mut backend_error = None;
    for (i, t) in threads.into_iter().enumerate() {
        match t.join() {
            Ok(Err(e)) => {
                backend_error.get_or_insert(e.context(format!("back end {}", i + 1)));
            }
            Err(_) => {
                backend_error.get_or_insert(anyhow::anyhow!("back end {} panicked", i + 1));
            }
            Ok(Ok(())) => {}
        }
    }
    match (result, backend_error) {
        (Err(e), Some(b)) => Err(e.context(format!("{b:#}"))),
        (Err(e), None) => Err(e),
        (Ok(()), Some(e)) => Err(e),
        (Ok(()), None) => Ok(()),
    }
}

/// Largest side of the live coordinator's simulated eye view, pixels.
pub const EYE_VIEW_MAX_SIDE: u32 = 480;

/// The live coordinator's eye view of a light field display: what an eye at
/// `eye` sees (the simulator of `parallax simulate`), from every
/// projector's streamed image, as sRGB 8-bit RGB.
pub fn eye_view(
    display: &Display,
    images: &[StreamImage],
    eye: [f64; 3],
) -> Result<(u32, u32, Vec<u8>)> {
    use parallax_backend::simulate;
    let mut linear = vec![Vec::new(); display.projectors.len()];
    for im in images {
        let slot = linear
            .get_mut(im.projector as usize)
            .context("a streamed image names a projector the display lacks")?;
        *slot = simulate::linear_from_srgb8(&im.rgb8);
    }
    if let Some(i) = linear.iter().position(Vec::is_empty) {
        bail!(
            "eye view: no image of projector '{}' this frame",
            display.projectors[i].id
        );
    }
    let res = simulate::default_resolution(display, EYE_VIEW_MAX_SIDE);
    let img = simulate::simulate(display, &linear, eye, res)?;
    let rgb = parallax_backend::output::rgb8(&img);
    Ok((res[0], res[1], rgb))
}

#[cfg(test)]
mod tests {
    use super::{plan, Plan};

    #[test]
    fn sessions_are_planned_from_the_launcher_the_flag_and_the_display() {
        let unread = || -> anyhow::Result<usize> { panic!("the display is not needed") };
        assert_eq!(plan(true, Some(3), unread).unwrap(), Plan::Mpi);
        assert_eq!(
            plan(false, Some(3), unread).unwrap(),
            Plan::Embedded { backends: 3 }
        );
        assert_eq!(
            plan(false, None, || Ok(4)).unwrap(),
            Plan::Embedded { backends: 4 }
        );
        let e = plan(false, Some(0), unread).unwrap_err().to_string();
        assert!(e.contains("--backends 0"), "{e}");
        let e = plan(false, None, || anyhow::bail!("display.toml: no projectors"));
        assert!(e.unwrap_err().to_string().contains("display.toml"));
    }
}
