//! The out-of-core octree database, `.pxo` (G10 §5 "Data preprocessing",
//! G08 §3, L12 §4.1), as one stage: its format, writing, reading, the import
//! that builds it and what `parallax info` shows.
//!
//! The volume is cut into bricks of B³ voxels (B = 32 by default) organised in
//! an octree whose root covers the cubical power-of-two domain B·2^L. Every
//! brick is stored with [`OVERLAP`] extra voxels on every side (so it holds
//! (B+4)³ values) which makes it self-contained for trilinear interpolation
//! and central-difference gradients (G08 §3). Level 0 is the root; level L
//! holds the source voxels. A level-l voxel is the average of the 2×2×2
//! level-(l+1) voxels it covers (those inside the volume), so inner nodes are
//! the filtered version of their children at the same B³ resolution; of a
//! label volume it is one of the labels it covers (`import::label_of`).
//!
//! * [`layout`]: the geometry of levels, bricks and nodes.
//! * [`format`]: the on-disk header, node records, trailer and footer.
//! * [`codec`]: brick quantisation (8/16 bit against the brick's own range,
//!   G10 §5), compression and checksums.
//! * [`writer`] and [`reader`]: crash-safe writing, random access reading.
//! * [`import`]: volume → `.pxo`; [`info`]: what `parallax info` shows.

pub mod cells;
pub mod codec;
pub mod format;
pub mod import;
pub mod info;
pub mod layout;
pub mod reader;
pub mod writer;

pub use cells::{Brick, LayerBricks};
pub use codec::BrickEncoding;
pub use format::{Header, NodeRecord, Summary, MAX_LABELS};
pub use import::{import, ImportOptions, ImportReport, PyramidReuse};
pub use info::label_list;
pub use layout::{NodeKey, OctreeLayout, OVERLAP};
pub use reader::OctreeDb;
pub use writer::OctreeWriter;
