//! Random-access reading of a `.pxo`: the header and node table are read at
//! open; each brick is read on its own with a positioned read, checked against
//! its CRC and decoded. Every error names the file and, for a brick, which one.

use super::cells::{self, Brick};
use super::codec::{self, BrickEncoding, Framing};
use super::format::{
    bincode_config, Footer, Header, HeaderV4, NodeRecord, Summary, Trailer, TrailerV5, TrailerV6,
    CELLS_VERSION, FOOTER_LEN, LABELS_VERSION, MAGIC, MAX_LABELS, OLDEST_VERSION, PREAMBLE_LEN,
    SPLITS_VERSION, VERSION, WORLD_VERSION,
};
use super::layout::{NodeKey, OctreeLayout, OVERLAP};
use anyhow::{bail, Context, Result};
use std::collections::HashMap;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

pub struct OctreeDb {
    path: PathBuf,
    file: File,
    file_len: u64,
    /// How bricks are framed (from the format version).
    framing: Framing,
    /// Bytes of macrocell ranges at the end of each brick blob (format 4;
    /// 0 before, or where the brick size has no macrocells).
    cells_len: usize,
    pub header: Header,
    pub nodes: Vec<NodeRecord>,
    pub summary: Summary,
    index: HashMap<NodeKey, usize>,
    /// The header's and the node table's checksums: which database this is
    /// (the node table holds every brick's checksum).
    identity: u64,
}

impl OctreeDb {
    pub fn open(path: &Path) -> Result<Self> {
        let name = path.display();
        let file = File::open(path).with_context(|| format!("{name}: cannot open"))?;
        let file_len = file.metadata()?.len();
        let mut pre = [0u8; PREAMBLE_LEN];
        let got = file.read_at(&mut pre, 0)?;
        if got < MAGIC.len() || pre[0..8] != MAGIC {
            bail!("{name}: not a Parallax octree database (bad magic)");
        }
        if file_len < (PREAMBLE_LEN + FOOTER_LEN) as u64 {
            bail!("{name}: truncated ({file_len} bytes)");
        }
        let version = u32::from_le_bytes(pre[8..12].try_into().unwrap());
        if !(OLDEST_VERSION..=VERSION).contains(&version) {
            bail!(
                "{name}: format version {version} is not supported (this build reads {OLDEST_VERSION} to {VERSION})"
            );
        }
        let framing = if version == 1 {
            Framing::Untagged
        } else {
            Framing::Tagged
        };
        let head_len = u32::from_le_bytes(pre[12..16].try_into().unwrap()) as u64;
        let head_crc = u32::from_le_bytes(pre[16..20].try_into().unwrap());
        if head_len > file_len - (PREAMBLE_LEN + FOOTER_LEN) as u64 {
            bail!("{name}: header length {head_len} exceeds the file");
        }
        let mut head = vec![0u8; head_len as usize];
        file.read_exact_at(&mut head, PREAMBLE_LEN as u64)?;
        if crc32fast::hash(&head) != head_crc {
            bail!("{name}: header checksum mismatch (corrupt header)");
        }
        let header: Header = if version >= SPLITS_VERSION {
            bincode::serde::decode_from_slice(&head, bincode_config())
                .with_context(|| format!("{name}: corrupt header"))?
                .0
        } else {
            let (old, _): (HeaderV4, usize) =
                bincode::serde::decode_from_slice(&head, bincode_config())
                    .with_context(|| format!("{name}: corrupt header"))?;
            old.upgrade()
        };

        let mut foot = [0u8; FOOTER_LEN];
        file.read_exact_at(&mut foot, file_len - FOOTER_LEN as u64)?;
        let footer = Footer::from_bytes(&foot).with_context(|| {
            format!("{name}: no footer (the file is truncated or was not written completely)")
        })?;
        let data_start = PREAMBLE_LEN as u64 + head_len;
        if footer.trailer_offset < data_start
            || footer.trailer_offset.checked_add(footer.trailer_len)
                != Some(file_len - FOOTER_LEN as u64)
        {
            bail!("{name}: footer points outside the file (truncated or corrupt)");
        }
        let mut tbytes = vec![0u8; footer.trailer_len as usize];
        file.read_exact_at(&mut tbytes, footer.trailer_offset)?;
        if crc32fast::hash(&tbytes) != footer.trailer_crc {
            bail!("{name}: node table checksum mismatch (corrupt node table)");
        }
        let trailer: Trailer = if version >= WORLD_VERSION {
            bincode::serde::decode_from_slice(&tbytes, bincode_config())
                .with_context(|| format!("{name}: corrupt node table"))?
                .0
        } else if version >= LABELS_VERSION {
            let (old, _): (TrailerV6, usize) =
                bincode::serde::decode_from_slice(&tbytes, bincode_config())
                    .with_context(|| format!("{name}: corrupt node table"))?;
            old.upgrade()
        } else {
            let (old, _): (TrailerV5, usize) =
                bincode::serde::decode_from_slice(&tbytes, bincode_config())
                    .with_context(|| format!("{name}: corrupt node table"))?;
            old.upgrade()
        };

        check_header(&header).map_err(|e| anyhow::anyhow!("{name}: header: {e}"))?;
        if let Some(labels) = &trailer.summary.labels {
            if labels.len() > MAX_LABELS || labels.windows(2).any(|w| w[0] >= w[1]) {
                bail!(
                    "{name}: summary: the label list ({} labels) is not {MAX_LABELS} or fewer distinct labels in ascending order",
                    labels.len()
                );
            }
        }
        let layout = header.layout;
        if trailer.nodes.len() > layout.node_count() {
            bail!(
                "{name}: node table lists {} nodes, more than the {} of a {:?} octree with bricks of {}",
                trailer.nodes.len(),
                layout.node_count(),
                layout.dims,
                layout.brick
            );
        }
        let cells_len = if version >= CELLS_VERSION {
            cells::stored_len(layout.brick)
        } else {
            0
        };
        let max_blob = codec::max_encoded_len(layout.stored_len(), header.encoding) + cells_len;
        let mut index = HashMap::with_capacity(trailer.nodes.len());
        for (i, n) in trailer.nodes.iter().enumerate() {
            if !layout.contains(n.key) {
                bail!("{name}: node {} lies outside the octree", n.key);
            }
            if n.is_stored()
                && (n.offset < data_start
                    || n.offset
                        .checked_add(n.len as u64)
                        .is_none_or(|e| e > footer.trailer_offset))
            {
                bail!("{name}: brick {} points outside the brick area", n.key);
            }
            if n.is_stored() && (n.len as usize) <= cells_len {
                bail!(
                    "{name}: brick {} is {} bytes, too short for its {cells_len} bytes of macrocells",
                    n.key,
                    n.len
                );
            }
            if n.len as usize > max_blob {
                bail!(
                    "{name}: brick {} is {} bytes, more than a brick can encode to ({max_blob})",
                    n.key,
                    n.len
                );
            }
            if n.min.is_nan() || n.max.is_nan() || n.min > n.max {
                bail!("{name}: brick {} has range [{}, {}]", n.key, n.min, n.max);
            }
            if index.insert(n.key, i).is_some() {
                bail!("{name}: node {} is listed twice", n.key);
            }
        }
        // Stored bricks never share bytes.
        let mut spans: Vec<(u64, u64, NodeKey)> = trailer
            .nodes
            .iter()
            .filter(|n| n.is_stored())
            .map(|n| (n.offset, n.offset + n.len as u64, n.key))
            .collect();
        spans.sort_unstable();
        if let Some(w) = spans.windows(2).find(|w| w[1].0 < w[0].1) {
            bail!(
                "{name}: bricks {} and {} overlap in the file (offsets {} and {})",
                w[0].2,
                w[1].2,
                w[0].0,
                w[1].0
            );
        }
        Ok(OctreeDb {
            path: path.to_path_buf(),
            file,
            file_len,
            framing,
            cells_len,
            header,
            nodes: trailer.nodes,
            summary: trailer.summary,
            index,
            identity: (head_crc as u64) << 32 | footer.trailer_crc as u64,
        })
    }

    /// Which database this is: equal for two copies of one file, different
    /// (but for a 2^-64 chance) for two files.
    pub fn identity(&self) -> u64 {
        self.identity
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn file_len(&self) -> u64 {
        self.file_len
    }

    pub fn layout(&self) -> &OctreeLayout {
        &self.header.layout
    }

    pub fn encoding(&self) -> BrickEncoding {
        self.header.encoding
    }

    /// How this file's bricks are framed (format 1 or 2).
    pub fn framing(&self) -> Framing {
        self.framing
    }

    pub fn node(&self, key: NodeKey) -> Option<&NodeRecord> {
        self.index.get(&key).map(|&i| &self.nodes[i])
    }

    /// A stored brick's record and bytes as they are on disk, unchecked, or
    /// `None` for an empty node.
    fn read_raw(&self, key: NodeKey) -> Result<Option<(&NodeRecord, Vec<u8>)>> {
        let name = self.path.display();
        let rec = self
            .node(key)
            .with_context(|| format!("{name}: brick {key} does not exist"))?;
        if !rec.is_stored() {
            return Ok(None);
        }
        let mut bytes = vec![0u8; rec.len as usize];
        self.file
            .read_exact_at(&mut bytes, rec.offset)
            .with_context(|| format!("{name}: brick {key} (offset {}): read failed", rec.offset))?;
        Ok(Some((rec, bytes)))
    }

    /// A stored brick's encoded values as they are on disk (checksum
    /// checked; the macrocell ranges of format 4 left out), or `None` for an
    /// empty node.
    pub fn read_stored(&self, key: NodeKey) -> Result<Option<Vec<u8>>> {
        let Some((rec, mut bytes)) = self.read_raw(key)? else {
            return Ok(None);
        };
        anyhow::ensure!(
            codec::checksum(&bytes) == rec.crc,
            "{}: brick {key} (offset {}): checksum mismatch",
            self.path.display(),
            rec.offset
        );
        bytes.truncate(bytes.len() - self.cells_len);
        Ok(Some(bytes))
    }

    /// Whether the bricks carry their macrocell ranges (format 4).
    pub fn stores_cells(&self) -> bool {
        self.cells_len > 0
    }

    /// Reads, checks and decodes a stored brick: (B+4)³ data values, x fastest.
    /// An empty (not stored) node decodes to `None`.
    pub fn read_brick(&self, key: NodeKey) -> Result<Option<Vec<f32>>> {
        Ok(self.read_brick_cells(key)?.map(|b| b.values))
    }

    /// A whole level's voxels, reassembled from its bricks' interiors (x
    /// fastest, `layout().level_dims(level)` of them); an empty node's are
    /// NaN. For tests and checks of what import stored.
    pub fn read_level(&self, level: u32) -> Result<Vec<f32>> {
        let l = &self.header.layout;
        let (d, nb, b, side) = (
            l.level_dims(level),
            l.level_bricks(level),
            l.brick,
            l.stored_side(),
        );
        let mut grid = vec![f32::NAN; d[0] * d[1] * d[2]];
        for z in 0..nb[2] {
            for y in 0..nb[1] {
                for x in 0..nb[0] {
                    let key = NodeKey::new(level as u8, x as u32, y as u32, z as u32);
                    let Some(v) = self.read_brick(key)? else {
                        continue;
                    };
                    for k in 0..b.min(d[2] - z * b) {
                        for j in 0..b.min(d[1] - y * b) {
                            let row = ((k + OVERLAP) * side + j + OVERLAP) * side + OVERLAP;
                            let n = b.min(d[0] - x * b);
                            let at = ((z * b + k) * d[1] + y * b + j) * d[0] + x * b;
                            grid[at..at + n].copy_from_slice(&v[row..row + n]);
                        }
                    }
                }
            }
        }
        Ok(grid)
    }

    /// [`read_brick`](Self::read_brick) with the brick's macrocell ranges
    /// where the file stores them (format 4).
    pub fn read_brick_cells(&self, key: NodeKey) -> Result<Option<Brick>> {
        let name = self.path.display();
        let Some((rec, bytes)) = self.read_raw(key)? else {
            return Ok(None);
        };
        let fail = |e: codec::DecodeError| {
            anyhow::anyhow!("{name}: brick {key} (offset {}): {e}", rec.offset)
        };
        let computed = codec::checksum(&bytes);
        if computed != rec.crc {
            return Err(fail(codec::DecodeError::Checksum {
                stored: rec.crc,
                computed,
            }));
        }
        let (blob, cell_bytes) = bytes.split_at(bytes.len() - self.cells_len);
        let values = codec::decode_checked(
            blob,
            rec.min,
            rec.max,
            self.header.encoding,
            self.header.layout.stored_len(),
            self.framing,
        )
        .map_err(fail)?;
        let cells = (self.cells_len > 0).then(|| cells::decode(cell_bytes, rec.min, rec.max));
        Ok(Some(Brick {
            values,
            cells,
            layered: None,
        }))
    }
}

/// Largest brick side a database may declare (bricks of (B+4)³ values).
pub const MAX_BRICK: usize = 512;
/// Largest volume side a database may declare (voxels).
pub const MAX_DIM: usize = 1 << 24;

/// The header's figures against each other and against stated limits,
/// before anything is computed from them (a crafted or corrupt header must
/// not divide by zero, overflow or allocate without bound).
fn check_header(h: &Header) -> Result<()> {
    let l = &h.layout;
    if !(1..=MAX_BRICK).contains(&l.brick) {
        bail!("brick {} is outside 1..={MAX_BRICK}", l.brick);
    }
    if l.dims.iter().any(|&d| !(1..=MAX_DIM).contains(&d)) {
        bail!("dims {:?}: each must be in 1..={MAX_DIM}", l.dims);
    }
    if h.info.dims != l.dims {
        bail!(
            "dims {:?} of the volume differ from dims {:?} of the octree",
            h.info.dims,
            l.dims
        );
    }
    if h.info.spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        bail!("spacing {:?}: each must be finite and > 0", h.info.spacing);
    }
    let iso = OctreeLayout::new(l.dims, l.brick);
    if l.levels != iso.levels && l.splits == iso.splits {
        bail!(
            "levels {} does not match dims {:?} with bricks of {} ({} levels)",
            l.levels,
            l.dims,
            l.brick,
            iso.levels
        );
    }
    let fitted = OctreeLayout::for_spacing(l.dims, l.brick, h.info.spacing);
    if *l != iso && *l != fitted {
        bail!(
            "levels {} with splits {:?} match neither the isotropic octree over dims {:?} with bricks of {} ({} levels) nor the one for spacing {:?} ({} levels, splits {:?})",
            l.levels,
            l.splits,
            l.dims,
            l.brick,
            iso.levels,
            h.info.spacing,
            fitted.levels,
            fitted.splits
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::format::{Footer, Trailer};
    use crate::store::writer::NodeStats;
    use crate::store::OctreeWriter;
    use crate::volume::{VolumeInfo, VoxelType};

    /// An 8³ volume in bricks of 4: the root and its eight children, all
    /// stored.
    fn small_db(path: &Path) {
        let layout = OctreeLayout::new([8, 8, 8], 4);
        assert_eq!(layout.levels, 2);
        let header = Header {
            info: VolumeInfo {
                dims: [8, 8, 8],
                spacing: [1.0; 3],
                voxel_type: VoxelType::U8,
            },
            layout,
            encoding: BrickEncoding::U8Range,
            empty_below: None,
            source: "crafted".into(),
        };
        let mut w = OctreeWriter::create(path, &header).unwrap();
        let values = vec![10.0f32; layout.stored_len()];
        let mut blob = codec::encode(
            &values,
            0.0,
            10.0,
            BrickEncoding::U8Range,
            codec::Codec::DEFAULT,
        );
        blob.extend(cells::encode(
            &cells::ranges(4, |i| Some(values[i] as f64)),
            0.0,
            10.0,
        ));
        let stats = NodeStats {
            min: 0.0,
            max: 10.0,
            mean: 7.0,
            variance: 0.0,
        };
        w.add(NodeKey::root(), stats, Some(&blob)).unwrap();
        for c in layout.children(NodeKey::root()) {
            w.add(c, stats, Some(&blob)).unwrap();
        }
        w.finish(Summary::default()).unwrap();
    }

    /// Rewrites the header in place (same encoded length), with a valid CRC:
    /// what a crafted file looks like.
    fn craft_header(path: &Path, f: impl FnOnce(&mut Header)) {
        let mut b = std::fs::read(path).unwrap();
        let len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        let (mut h, _): (Header, usize) =
            bincode::serde::decode_from_slice(&b[20..20 + len], bincode_config()).unwrap();
        f(&mut h);
        let enc = bincode::serde::encode_to_vec(&h, bincode_config()).unwrap();
        assert_eq!(enc.len(), len);
        b[16..20].copy_from_slice(&crc32fast::hash(&enc).to_le_bytes());
        b[20..20 + len].copy_from_slice(&enc);
        std::fs::write(path, b).unwrap();
    }

    fn craft_trailer(path: &Path, f: impl FnOnce(&mut Trailer)) {
        let mut b = std::fs::read(path).unwrap();
        let n = b.len();
        let foot = Footer::from_bytes(&b[n - FOOTER_LEN..].try_into().unwrap()).unwrap();
        let (start, len) = (foot.trailer_offset as usize, foot.trailer_len as usize);
        let (mut t, _): (Trailer, usize) =
            bincode::serde::decode_from_slice(&b[start..start + len], bincode_config()).unwrap();
        f(&mut t);
        let enc = bincode::serde::encode_to_vec(&t, bincode_config()).unwrap();
        assert_eq!(enc.len(), len);
        b[start..start + len].copy_from_slice(&enc);
        let foot = Footer {
            trailer_crc: crc32fast::hash(&enc),
            ..foot
        };
        b[n - FOOTER_LEN..].copy_from_slice(&foot.to_bytes());
        std::fs::write(path, b).unwrap();
    }

    #[test]
    fn crafted_headers_and_tables_are_refused_naming_the_field() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("good.pxo");
        small_db(&good);
        let db = OctreeDb::open(&good).unwrap();
        assert_eq!(db.nodes.len(), 9);
        assert_eq!(db.read_brick(NodeKey::root()).unwrap().unwrap()[0], 10.0);
        type Craft = Box<dyn Fn(&Path)>;
        let cases: Vec<(&str, Craft, &str)> = vec![
            (
                "zero levels",
                Box::new(|p| craft_header(p, |h| h.layout.levels = 0)),
                "levels 0",
            ),
            (
                "zero brick",
                Box::new(|p| craft_header(p, |h| h.layout.brick = 0)),
                "brick 0",
            ),
            (
                "huge dims",
                Box::new(|p| {
                    craft_header(p, |h| {
                        h.layout.dims = [1 << 40, 8, 8];
                        h.info.dims = [1 << 40, 8, 8];
                    })
                }),
                "dims",
            ),
            (
                "dims disagree",
                Box::new(|p| craft_header(p, |h| h.info.dims = [9, 8, 8])),
                "dims",
            ),
            (
                "too many levels",
                Box::new(|p| craft_header(p, |h| h.layout.levels = 40)),
                "levels 40",
            ),
            (
                "splits of no octree",
                Box::new(|p| craft_header(p, |h| h.layout.splits = [2, 0, 0])),
                "splits [2, 0, 0]",
            ),
            (
                "overlapping offsets",
                Box::new(|p| craft_trailer(p, |t| t.nodes[2].offset = t.nodes[1].offset + 1)),
                "overlap",
            ),
            (
                "huge brick record",
                Box::new(|p| craft_trailer(p, |t| t.nodes[1].len = u32::MAX)),
                "brick level 1",
            ),
            (
                "a node listed twice",
                Box::new(|p| craft_trailer(p, |t| t.nodes[2].key = t.nodes[1].key)),
                "twice",
            ),
            (
                "a reversed range",
                Box::new(|p| craft_trailer(p, |t| t.nodes[3].min = f32::NAN)),
                "range",
            ),
        ];
        for (what, craft, field) in cases {
            let p = dir.path().join("bad.pxo");
            std::fs::copy(&good, &p).unwrap();
            craft(&p);
            let e = match OctreeDb::open(&p) {
                Ok(_) => panic!("{what}: accepted"),
                Err(e) => format!("{e:#}"),
            };
            assert!(e.contains("bad.pxo") && e.contains(field), "{what}: {e}");
        }
    }

    #[test]
    fn a_brick_whose_size_prefix_lies_is_refused_before_allocation() {
        let values = vec![1.0f32; 64];
        let mut blob = codec::encode(
            &values,
            0.0,
            2.0,
            BrickEncoding::U8Range,
            codec::Codec::DEFAULT,
        );
        blob[1..5].copy_from_slice(&u32::MAX.to_le_bytes());
        let crc = crc32fast::hash(&blob);
        let e = codec::tests::decode(
            &blob,
            crc,
            0.0,
            2.0,
            BrickEncoding::U8Range,
            64,
            Framing::Tagged,
        )
        .unwrap_err();
        assert!(matches!(e, codec::DecodeError::Size { .. }), "{e}");
    }
}
