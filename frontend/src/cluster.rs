//! The MPI transport (DESIGN.md "Process model"): rank 0 is the front end,
//! ranks 1…K−1 the back ends. A message is broadcast as its length, then its
//! bincode bytes; each back end's reply goes to rank 0 point to point, and
//! rank 0 waits for all of them before the next frame (swap lock).
//! MPI stays here, at the edge: the front end and the back ends only see the
//! [`Transport`] and [`Link`] traits, exactly as in the embedded mode.

use anyhow::Result;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;
use parallax_common::protocol::{decode, encode, FrameStats, Link, ToBackend, Transport};

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
}

/// A back end's side.
pub struct MpiLink {
    world: SimpleCommunicator,
}

pub fn transport(world: SimpleCommunicator) -> MpiTransport {
    MpiTransport { world }
}

pub fn link(world: SimpleCommunicator) -> MpiLink {
    MpiLink { world }
}

fn broadcast_bytes(world: &SimpleCommunicator, bytes: Option<Vec<u8>>) -> Vec<u8> {
    let root = world.process_at_rank(0);
    let mut len = bytes.as_ref().map_or(0u64, |b| b.len() as u64);
    root.broadcast_into(&mut len);
    let mut buf = bytes.unwrap_or_else(|| vec![0u8; len as usize]);
    root.broadcast_into(&mut buf[..]);
    buf
}

impl Transport for MpiTransport {
    fn backends(&self) -> usize {
        self.world.size() as usize - 1
    }

    fn broadcast(&mut self, msg: &ToBackend) -> Result<()> {
        broadcast_bytes(&self.world, Some(encode(msg)));
        Ok(())
    }

    fn gather(&mut self) -> Result<Vec<FrameStats>> {
        let mut out = Vec::with_capacity(self.backends());
        for r in 1..self.world.size() {
            let (bytes, _) = self.world.process_at_rank(r).receive_vec::<u8>();
            out.push(decode::<FrameStats>(&bytes)?);
        }
        Ok(out)
    }
}

impl Link for MpiLink {
    fn rank(&self) -> u32 {
        self.world.rank() as u32
    }

    fn receive(&mut self) -> Result<ToBackend> {
        decode(&broadcast_bytes(&self.world, None))
    }

    fn reply(&mut self, stats: &FrameStats) -> Result<()> {
        self.world.process_at_rank(0).send(&encode(stats)[..]);
        Ok(())
    }
}
