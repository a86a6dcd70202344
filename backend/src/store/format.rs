//! The `.pxo` file layout. One file, readable brick by brick:
//!
//! ```text
//! 0      magic "PXOCTREE", version u32, header length u32, header CRC-32 u32
//! 20     header (bincode): volume info, brick size, levels, encoding
//! …      brick blobs (codec tag, compressed values, then the macrocell
//!        ranges; each with its own CRC-32 in its node record)
//! T      trailer (bincode): node records (sorted by level, z, y, x) and the
//!        import summary
//! end−32 footer: trailer offset u64, trailer length u64, trailer CRC-32 u32,
//!        reserved u32, magic "PXOEND\0\0"
//! ```
//!
//! All integers are little endian. The writer writes the trailer and footer
//! last and renames the file into place only when complete, so a reader never
//! sees a half-written database under its final name.

use super::codec::BrickEncoding;
use super::layout::{NodeKey, OctreeLayout};
use crate::volume::VolumeInfo;
use serde::{Deserialize, Serialize};

pub const MAGIC: [u8; 8] = *b"PXOCTREE";
pub const FOOTER_MAGIC: [u8; 8] = *b"PXOEND\0\0";
/// The format written. Format 1 (LZ4 bricks without a codec tag) still reads;
/// format 2 tags every brick with its codec; format 3 adds the unit-step
/// quantisation bit to the tag (lossless 8/16-bit integer bricks; older
/// builds refuse the file by its version rather than misread a brick);
/// format 4 appends each brick's macrocell ranges to its blob, under its
/// checksum (`cells`: two bytes a cell; formats 1–3 get them computed when
/// a brick is uploaded); format 5 records which axes each level halves
/// (`OctreeLayout::splits`: levels over thick slices halve only the finer
/// axes; formats 1–4 are isotropic octrees); format 6 records a label
/// volume's labels in the import summary (`Summary::labels`); format 7
/// records the scanner geometry the importer read (`Summary::world`).
pub const VERSION: u32 = 7;
/// The first format whose bricks carry their macrocell ranges.
pub const CELLS_VERSION: u32 = 4;
/// The first format whose levels may halve only some axes.
pub const SPLITS_VERSION: u32 = 5;
/// The first format whose summary may list a label volume's labels.
pub const LABELS_VERSION: u32 = 6;
/// The first format whose summary may hold the scanner geometry.
pub const WORLD_VERSION: u32 = 7;
/// The oldest format read.
pub const OLDEST_VERSION: u32 = 1;
/// Bytes before the header: magic, version, header length, header CRC.
pub const PREAMBLE_LEN: usize = 20;
pub const FOOTER_LEN: usize = 32;

/// The bincode configuration of every structure in the file (fixed-width
/// little-endian integers, so record sizes do not depend on their values).
pub fn bincode_config() -> impl bincode::config::Config {
    bincode::config::standard()
        .with_little_endian()
        .with_fixed_int_encoding()
        // What decoding a header or node table may claim: a length that a
        // crafted file declares is refused before it is allocated (the
        // limit changes nothing written). 1 GiB of node table is about 16
        // million nodes.
        .with_limit::<{ 1 << 30 }>()
}

/// What is known before any voxel is read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub info: VolumeInfo,
    pub layout: OctreeLayout,
    pub encoding: BrickEncoding,
    /// Bricks whose values are all below this were dropped (not stored).
    pub empty_below: Option<f32>,
    /// Name of the file the database was imported from.
    pub source: String,
}

/// The layout as formats 1–4 store it: every level halves all three axes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayoutV4 {
    pub dims: [usize; 3],
    pub brick: usize,
    pub levels: u32,
}

/// The header of formats 1–4.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeaderV4 {
    pub info: VolumeInfo,
    pub layout: LayoutV4,
    pub encoding: BrickEncoding,
    pub empty_below: Option<f32>,
    pub source: String,
}

impl HeaderV4 {
    /// The same header in this build's terms (an isotropic octree). A
    /// level count out of range is kept as it is, for the header check to
    /// name it.
    pub fn upgrade(self) -> Header {
        let l = self.layout;
        let all = super::layout::every_level_splits(l.levels);
        Header {
            info: self.info,
            layout: OctreeLayout {
                dims: l.dims,
                brick: l.brick,
                levels: l.levels,
                splits: [all; 3],
            },
            encoding: self.encoding,
            empty_below: self.empty_below,
            source: self.source,
        }
    }
}

/// One node of the octree, stored or empty.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeRecord {
    pub key: NodeKey,
    /// Range of the stored values, overlap included (the range the 8-bit codes
    /// map to, and what empty-space tests under a transfer function use).
    pub min: f32,
    pub max: f32,
    /// Mean and variance of the node's own voxels (inside the volume, overlap
    /// excluded) — B10 §4.5 variance bricking.
    pub mean: f32,
    pub variance: f32,
    /// Where the brick's bytes are; `len == 0` for an empty (dropped) brick.
    pub offset: u64,
    pub len: u32,
    pub crc: u32,
}

impl NodeRecord {
    pub fn is_stored(&self) -> bool {
        self.len > 0
    }
}

/// Figures gathered during import.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Smallest and largest source value.
    pub value_min: f32,
    pub value_max: f32,
    /// Quantisation error of the stored source-level voxels, in data units.
    pub quant_rms: f64,
    pub quant_max: f64,
    /// Voxels the error figures were measured on.
    pub quant_samples: u64,
    /// A label volume (imported with `--labels`): the labels it holds,
    /// ascending. Its voxels are whole labels and its coarser levels keep
    /// labels (`store::import`), so a colour table can be checked against
    /// them before anything is drawn. `None`: a volume of values.
    pub labels: Option<Vec<u32>>,
    /// Where the volume lies in the scanner's patient space, as the source
    /// file says (DICOM, NIfTI's sform or qform, NRRD's space): the affine
    /// map, three rows `[a, b, c, t]`, from volume space (data units from
    /// the first voxel's corner) to patient coordinates in LPS millimetres
    /// (DICOM's frame: x to the patient's left, y posterior, z superior).
    /// A layer placed by `transform = "scanner"` uses its own and the scene
    /// volume's. `None`: the source has none.
    pub world: Option<[[f64; 4]; 3]>,
}

/// The most distinct labels a label volume may hold.
pub const MAX_LABELS: usize = 1 << 16;

/// The summary of formats 1–5 (no labels).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SummaryV5 {
    pub value_min: f32,
    pub value_max: f32,
    pub quant_rms: f64,
    pub quant_max: f64,
    pub quant_samples: u64,
}

/// The trailer of formats 1–5.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrailerV5 {
    pub nodes: Vec<NodeRecord>,
    pub summary: SummaryV5,
}

impl TrailerV5 {
    /// The same trailer in this build's terms (a volume of values).
    pub fn upgrade(self) -> Trailer {
        let s = self.summary;
        TrailerV6 {
            nodes: self.nodes,
            summary: SummaryV6 {
                value_min: s.value_min,
                value_max: s.value_max,
                quant_rms: s.quant_rms,
                quant_max: s.quant_max,
                quant_samples: s.quant_samples,
                labels: None,
            },
        }
        .upgrade()
    }
}

/// The summary of format 6 (labels, no scanner geometry).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SummaryV6 {
    pub value_min: f32,
    pub value_max: f32,
    pub quant_rms: f64,
    pub quant_max: f64,
    pub quant_samples: u64,
    pub labels: Option<Vec<u32>>,
}

/// The trailer of format 6.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrailerV6 {
    pub nodes: Vec<NodeRecord>,
    pub summary: SummaryV6,
}

impl TrailerV6 {
    /// The same trailer in this build's terms (no scanner geometry).
    pub fn upgrade(self) -> Trailer {
        let s = self.summary;
        Trailer {
            nodes: self.nodes,
            summary: Summary {
                value_min: s.value_min,
                value_max: s.value_max,
                quant_rms: s.quant_rms,
                quant_max: s.quant_max,
                quant_samples: s.quant_samples,
                labels: s.labels,
                world: None,
            },
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trailer {
    pub nodes: Vec<NodeRecord>,
    pub summary: Summary,
}

/// The fixed-size footer at the very end of the file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footer {
    pub trailer_offset: u64,
    pub trailer_len: u64,
    pub trailer_crc: u32,
}

impl Footer {
    pub fn to_bytes(self) -> [u8; FOOTER_LEN] {
        let mut b = [0u8; FOOTER_LEN];
        b[0..8].copy_from_slice(&self.trailer_offset.to_le_bytes());
        b[8..16].copy_from_slice(&self.trailer_len.to_le_bytes());
        b[16..20].copy_from_slice(&self.trailer_crc.to_le_bytes());
        b[24..32].copy_from_slice(&FOOTER_MAGIC);
        b
    }

    pub fn from_bytes(b: &[u8; FOOTER_LEN]) -> Option<Self> {
        if b[24..32] != FOOTER_MAGIC {
            return None;
        }
        Some(Footer {
            trailer_offset: u64::from_le_bytes(b[0..8].try_into().unwrap()),
            trailer_len: u64::from_le_bytes(b[8..16].try_into().unwrap()),
            trailer_crc: u32::from_le_bytes(b[16..20].try_into().unwrap()),
        })
    }
}
