//! The MPI transport (docs/design.md "Process model"): rank 0 is the front end,
//! ranks 1…K−1 the back ends. A message is broadcast as its length, then its
//! bincode bytes; each back end's reply goes to rank 0 point to point, and
//! rank 0 waits for all of them before the next frame (swap lock).
//! MPI stays here, at the edge: the front end and the back ends only see the
//! [`Transport`] and [`Link`] traits, exactly as in the embedded mode.
//!
//! Every wait is a non-blocking operation polled with short naps: a back end
//! waiting for the next frame sleeps instead of spinning a core (OpenMPI's
//! blocking calls busy-poll), and the front end's waits have a deadline
//! (the watchdog), so a stopped or hung rank is named instead of hanging the
//! wall.

use anyhow::Result;
use mpi::request::{Request, Scope};
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;
use parallax_common::protocol::{
    decode, encode, watchdog_error, FrameStats, Link, ToBackend, Transport, DEFAULT_WATCHDOG,
};
use std::time::{Duration, Instant};

/// Whether this process was started by an MPI launcher.
pub fn launched_by_mpi() -> bool {
    [
        "OMPI_COMM_WORLD_SIZE",
        "PMI_SIZE",
        "PMIX_RANK",
        "MPI_LOCALNRANKS",
    ]
    .iter()
    .any(|v| std::env::var_os(v).is_some())
}

/// Rank 0's side.
pub struct MpiTransport {
    world: SimpleCommunicator,
    watchdog: Option<Duration>,
}

/// A back end's side.
pub struct MpiLink {
    world: SimpleCommunicator,
}

pub fn transport(world: SimpleCommunicator) -> MpiTransport {
    MpiTransport {
        world,
        watchdog: Some(DEFAULT_WATCHDOG),
    }
}

pub fn link(world: SimpleCommunicator) -> MpiLink {
    MpiLink { world }
}

/// Ends the whole MPI job: every rank, including a stopped one, is killed by
/// the launcher. For failures after which no rank can be told to quit.
pub fn abort_job(code: i32) -> ! {
    SimpleCommunicator::world().abort(code)
}

/// Polls `req` until it completes, napping between tests (20 µs growing to
/// 1 ms). Past `deadline` the request cannot be abandoned (MPI keeps its
/// buffer), so the job is aborted after `on_timeout` has said why.
fn complete<'a, D: ?Sized, S: Scope<'a>>(
    mut req: Request<'a, D, S>,
    deadline: Option<Instant>,
    on_timeout: impl FnOnce(),
) {
    let mut nap = Duration::from_micros(20);
    loop {
        match req.test() {
            Ok(_) => return,
            Err(r) => req = r,
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            on_timeout();
            abort_job(1);
        }
        std::thread::sleep(nap);
        nap = (nap * 2).min(Duration::from_millis(1));
    }
}

fn broadcast_bytes(
    world: &SimpleCommunicator,
    bytes: Option<Vec<u8>>,
    deadline: Option<Instant>,
    timeout: Duration,
) -> Vec<u8> {
    let root = world.process_at_rank(0);
    let said = || {
        eprintln!(
            "error: a broadcast to the back ends did not complete within {:.0} s (a back end is stopped or hung; watchdog timeout, --watchdog)",
            timeout.as_secs_f64()
        )
    };
    let mut len = bytes.as_ref().map_or(0u64, |b| b.len() as u64);
    mpi::request::scope(|sc| complete(root.immediate_broadcast_into(sc, &mut len), deadline, said));
    let mut buf = bytes.unwrap_or_else(|| vec![0u8; len as usize]);
    mpi::request::scope(|sc| {
        complete(
            root.immediate_broadcast_into(sc, &mut buf[..]),
            deadline,
            said,
        )
    });
    buf
}

impl Transport for MpiTransport {
    fn backends(&self) -> usize {
        self.world.size() as usize - 1
    }

    fn broadcast(&mut self, msg: &ToBackend) -> Result<()> {
        let deadline = self.watchdog.map(|t| Instant::now() + t);
        let timeout = self.watchdog.unwrap_or_default();
        broadcast_bytes(&self.world, Some(encode(msg)?), deadline, timeout);
        Ok(())
    }

    fn gather(&mut self) -> Result<Vec<FrameStats>> {
        let deadline = self.watchdog.map(|t| Instant::now() + t);
        let mut pending: Vec<i32> = (1..self.world.size()).collect();
        let mut out = Vec::with_capacity(pending.len());
        let mut nap = Duration::from_micros(20);
        while !pending.is_empty() {
            let mut got = false;
            let mut i = 0;
            while i < pending.len() {
                let p = self.world.process_at_rank(pending[i]);
                if let Some(probed) = p.immediate_matched_probe() {
                    let (bytes, _) = probed.matched_receive_vec::<u8>();
                    out.push(decode::<FrameStats>(&bytes)?);
                    pending.swap_remove(i);
                    got = true;
                } else {
                    i += 1;
                }
            }
            if got {
                nap = Duration::from_micros(20);
                continue;
            }
            if deadline.is_some_and(|d| Instant::now() >= d) {
                pending.sort();
                let missing: Vec<u32> = pending.iter().map(|&r| r as u32).collect();
                return Err(watchdog_error(&missing, self.watchdog.unwrap_or_default()));
            }
            std::thread::sleep(nap);
            nap = (nap * 2).min(Duration::from_millis(1));
        }
        out.sort_by_key(|s| s.rank);
        Ok(out)
    }

    fn set_watchdog(&mut self, timeout: Option<Duration>) {
        self.watchdog = timeout;
    }
}

impl Link for MpiLink {
    fn rank(&self) -> u32 {
        self.world.rank() as u32
    }

    fn receive(&mut self) -> Result<ToBackend> {
        // A back end waits for the coordinator as long as it takes (an idle
        // live session), asleep between polls.
        decode(&broadcast_bytes(&self.world, None, None, Duration::ZERO))
    }

    fn reply(&mut self, stats: &FrameStats) -> Result<()> {
        self.world.process_at_rank(0).send(&encode(stats)?[..]);
        Ok(())
    }
}
