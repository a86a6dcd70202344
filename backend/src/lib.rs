//! Parallax back end. The pipeline reads top to bottom:
//! data (volume input) → store (octree import and reading) → reference
//! (the exact integral every image is measured against).

pub mod calibrate;
pub mod data;
pub mod geometry;
pub mod gpu;
pub mod index;
pub mod lenticular;
pub mod loader;
pub mod metric;
pub mod mpcdi;
pub mod node;
pub mod output;
pub mod overlay;
pub mod pick;
pub mod present;
pub mod quilt;
pub mod raycast;
pub mod reconstruct;
pub mod reference;
pub mod render;
pub mod simulate;
pub mod store;
pub mod volume;
