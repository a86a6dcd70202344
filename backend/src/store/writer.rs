//! Crash-safe writing of a `.pxo`: everything goes through [`AtomicFile`] (a
//! temporary file next to the destination) and is renamed into place only once
//! the trailer and footer are written and synced. An interrupted import leaves
//! whatever was at the destination untouched.

use super::format::{bincode_config, Footer, Header, NodeRecord, Summary, Trailer, MAGIC, VERSION};
use super::layout::NodeKey;
use anyhow::{Context, Result};
use parallax_common::atomic::AtomicFile;
use std::io::Write;
use std::path::Path;

pub struct OctreeWriter {
    out: AtomicFile,
    offset: u64,
    nodes: Vec<NodeRecord>,
}

/// Statistics of a node, computed by whoever built its brick.
#[derive(Clone, Copy, Debug)]
pub struct NodeStats {
    pub min: f32,
    pub max: f32,
    pub mean: f32,
    pub variance: f32,
}

impl OctreeWriter {
    pub fn create(path: &Path, header: &Header) -> Result<Self> {
        let mut out = AtomicFile::create(path)?;
        let head = bincode::serde::encode_to_vec(header, bincode_config())?;
        out.write_all(&MAGIC)?;
        out.write_all(&VERSION.to_le_bytes())?;
        out.write_all(&(head.len() as u32).to_le_bytes())?;
        out.write_all(&crc32fast::hash(&head).to_le_bytes())?;
        out.write_all(&head)?;
        let offset = (super::format::PREAMBLE_LEN + head.len()) as u64;
        Ok(OctreeWriter {
            out,
            offset,
            nodes: Vec::new(),
        })
    }

    /// Records a node; `stored` is its encoded brick, or `None` for an empty
    /// brick that is not stored.
    pub fn add(&mut self, key: NodeKey, stats: NodeStats, stored: Option<&[u8]>) -> Result<()> {
        let mut rec = NodeRecord {
            key,
            min: stats.min,
            max: stats.max,
            mean: stats.mean,
            variance: stats.variance,
            offset: 0,
            len: 0,
            crc: 0,
        };
        if let Some(bytes) = stored {
            anyhow::ensure!(!bytes.is_empty(), "brick {key}: empty encoding");
            self.out
                .write_all(bytes)
                .with_context(|| format!("{}: write failed", self.out.temp_path().display()))?;
            rec.offset = self.offset;
            rec.len = u32::try_from(bytes.len())?;
            rec.crc = crc32fast::hash(bytes);
            self.offset += bytes.len() as u64;
        }
        self.nodes.push(rec);
        Ok(())
    }

    /// Bytes written so far.
    pub fn bytes_written(&self) -> u64 {
        self.offset
    }

    /// Writes the trailer and footer, syncs, and renames the file into place.
    pub fn finish(mut self, summary: Summary) -> Result<u64> {
        let mut nodes = std::mem::take(&mut self.nodes);
        nodes.sort_by_key(|n| n.key);
        let trailer = bincode::serde::encode_to_vec(&Trailer { nodes, summary }, bincode_config())?;
        let footer = Footer {
            trailer_offset: self.offset,
            trailer_len: trailer.len() as u64,
            trailer_crc: crc32fast::hash(&trailer),
        };
        let mut out = self.out;
        let label = out.path().display().to_string();
        out.write_all(&trailer)
            .and_then(|_| out.write_all(&footer.to_bytes()))
            .with_context(|| format!("{label}: write failed"))?;
        out.commit()?;
        Ok(self.offset + trailer.len() as u64 + super::format::FOOTER_LEN as u64)
    }
}
