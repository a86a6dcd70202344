//! The `parallax` library beneath the command line: how a session starts
//! (embedded back-end threads, or ranks under `mpirun`), so that tests can
//! start the same sessions in-process.

pub mod cmd;
pub mod launch;
