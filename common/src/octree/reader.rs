//! Random-access reading of a `.pxo`: the header and node table are read at
//! open; each brick is read on its own with a positioned read, checked against
//! its CRC and decoded. Every error names the file and, for a brick, which one.

use super::codec::{self, BrickEncoding};
use super::format::{
    bincode_config, Footer, Header, NodeRecord, Summary, Trailer, FOOTER_LEN, MAGIC, PREAMBLE_LEN,
    VERSION,
};
use super::layout::{NodeKey, OctreeLayout};
use anyhow::{bail, Context, Result};
use std::collections::HashMap;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

pub struct OctreeDb {
    path: PathBuf,
    file: File,
    file_len: u64,
    pub header: Header,
    pub nodes: Vec<NodeRecord>,
    pub summary: Summary,
    index: HashMap<NodeKey, usize>,
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
        if version != VERSION {
            bail!("{name}: format version {version} is not supported (this build reads {VERSION})");
        }
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
        let (header, _): (Header, usize) =
            bincode::serde::decode_from_slice(&head, bincode_config())
                .with_context(|| format!("{name}: corrupt header"))?;

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
        let (trailer, _): (Trailer, usize) =
            bincode::serde::decode_from_slice(&tbytes, bincode_config())
                .with_context(|| format!("{name}: corrupt node table"))?;

        let layout = header.layout;
        let mut index = HashMap::with_capacity(trailer.nodes.len());
        for (i, n) in trailer.nodes.iter().enumerate() {
            if !layout.contains(n.key) {
                bail!("{name}: node {} lies outside the octree", n.key);
            }
            if n.is_stored()
                && (n.offset < data_start || n.offset + n.len as u64 > footer.trailer_offset)
            {
                bail!("{name}: brick {} points outside the brick area", n.key);
            }
            if index.insert(n.key, i).is_some() {
                bail!("{name}: node {} is listed twice", n.key);
            }
        }
        Ok(OctreeDb {
            path: path.to_path_buf(),
            file,
            file_len,
            header,
            nodes: trailer.nodes,
            summary: trailer.summary,
            index,
        })
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

    pub fn node(&self, key: NodeKey) -> Option<&NodeRecord> {
        self.index.get(&key).map(|&i| &self.nodes[i])
    }

    /// Reads, checks and decodes a stored brick: (B+4)³ data values, x fastest.
    /// An empty (not stored) node decodes to `None`.
    pub fn read_brick(&self, key: NodeKey) -> Result<Option<Vec<f32>>> {
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
            .with_context(|| format!("{name}: brick {key}: read failed"))?;
        let values = codec::decode(
            &bytes,
            rec.crc,
            rec.min,
            rec.max,
            self.header.encoding,
            self.header.layout.stored_len(),
        )
        .map_err(|e| anyhow::anyhow!("{name}: brick {key} (offset {}): {e}", rec.offset))?;
        Ok(Some(values))
    }
}
