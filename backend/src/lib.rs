//! Parallax back end. The pipeline reads top to bottom:
//! data (volume input) → store (octree import and reading) → reference
//! (the exact integral every image is measured against).

pub mod data;
pub mod geometry;
pub mod gpu;
pub mod index;
pub mod loader;
pub mod metric;
pub mod node;
pub mod output;
pub mod pick;
pub mod quilt;
pub mod raycast;
pub mod reconstruct;
pub mod reference;
pub mod render;
pub mod simulate;
pub mod store;
pub mod volume;
