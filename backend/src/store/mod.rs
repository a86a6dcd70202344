//! The octree store: import (volume → `.pxo`) and what `parallax info` shows.

pub mod import;
pub mod info;

pub use import::{import, ImportOptions, ImportReport};
