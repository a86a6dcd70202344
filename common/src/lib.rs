//! Parallax common: what the front end, the back ends and the tools share.
//!
//! * [`camera`]: placement and the MCOP ray of a pixel (G10 §4 Eq. 1).
//! * [`config`]: scene and display files.
//! * [`protocol`]: the messages between the front end and the back ends.
//! * [`volume`]: scalar volumes and slice-by-slice sources.
//! * [`tf`]: transfer functions and their pre-integration tables (G10 §4).
//! * [`tools`]: tools (clip plane, …) and the enhancers they drive (G10 §4).
//! * [`wall`]: generated light field walls (G10 §6).
//! * [`paths`]: paths as bytes on the wire, names checked before they become files.
//! * [`octree`]: the out-of-core octree database (`.pxo`) (G10 §5, G08 §3).

pub mod camera;
pub mod config;
pub mod octree;
pub mod paths;
pub mod protocol;
pub mod tf;
pub mod tools;
pub mod volume;
pub mod wall;
