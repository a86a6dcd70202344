//! Parallax common: what crosses the wire between the front end and the back
//! ends (configs, protocol, camera math, transfer functions, tools). The
//! `.pxo` store and volume input live in the back end.
//!
//! * [`atomic`]: the one way a file is written whole (temporary file, persist).
//! * [`camera`]: placement and the MCOP ray of a pixel (G10 §4 Eq. 1).
//! * [`config`]: scene and display files.
//! * [`lenticular`]: a Looking Glass's calibration and its sub-pixel mapping.
//! * [`protocol`]: the messages between the front end and the back ends.
//! * [`tf`]: transfer functions and their pre-integration tables (G10 §4).
//! * [`tools`]: tools (clip plane, …) and the enhancers they drive (G10 §4).
//! * [`wall`]: generated light field walls (G10 §6).
//! * [`present`]: how a display's images reach its outputs (windows, viewports).
//! * [`paths`]: paths as bytes on the wire, names checked before they become files.

pub mod atomic;
pub mod camera;
pub mod config;
pub mod lenticular;
pub mod overlay;
pub mod paths;
pub mod present;
pub mod protocol;
pub mod tf;
pub mod tools;
pub mod wall;

/// This process's resident memory (Linux: VmRSS of `/proc/self/status`),
/// bytes; 0 where it cannot be read.
pub fn resident_bytes() -> u64 {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return 0;
    };
    status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |kib| kib * 1024)
}
