//! The streaming NRRD writer.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{ensure, Context, Result};
use parallax_common::atomic::AtomicFile;

use crate::data::{check_finite, check_info, encode_samples};
use crate::volume::{VolumeInfo, VoxelType};

/// NRRD `type` name written for each voxel type.
fn type_name(t: VoxelType) -> &'static str {
    match t {
        VoxelType::U8 => "uint8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::F32 => "float",
        VoxelType::I8 => "int8",
        VoxelType::I32 => "int32",
        VoxelType::U32 => "uint32",
        VoxelType::F64 => "double",
    }
}

/// Streams a volume into an attached-header, raw, little-endian NRRD.
///
/// The file is written through [`AtomicFile`] and appears on [`finish`], so a
/// crash or an error never leaves a half-written volume under the final name
/// (the same rule as the database, docs/design.md "Data"). Dropping an unfinished
/// writer removes the temporary file.
///
/// [`finish`]: NrrdWriter::finish
pub struct NrrdWriter {
    path: PathBuf,
    out: AtomicFile,
    info: VolumeInfo,
    header_len: u64,
    written: u64,
    buf: Vec<u8>,
}

impl NrrdWriter {
    /// Creates the temporary file and writes the header.
    pub fn create(
        path: &Path,
        dims: [usize; 3],
        voxel_type: VoxelType,
        spacing: [f64; 3],
    ) -> Result<Self> {
        let label = path.display().to_string();
        let info = VolumeInfo {
            dims,
            spacing,
            voxel_type,
        };
        check_info(&label, &info, "dims", "spacing")?;
        let out = AtomicFile::create(path)?;
        let header = format!(
            "NRRD0004\n\
             # Complete NRRD file format specification at:\n\
             # http://teem.sourceforge.net/nrrd/format.html\n\
             type: {}\n\
             dimension: 3\n\
             sizes: {} {} {}\n\
             spacings: {} {} {}\n\
             endian: little\n\
             encoding: raw\n\n",
            type_name(voxel_type),
            dims[0],
            dims[1],
            dims[2],
            spacing[0],
            spacing[1],
            spacing[2]
        );
        let mut writer = NrrdWriter {
            path: path.to_path_buf(),
            out,
            info,
            header_len: header.len() as u64,
            written: 0,
            buf: Vec::new(),
        };
        writer
            .out
            .write_all(header.as_bytes())
            .with_context(|| format!("{label}: writing the header"))?;
        Ok(writer)
    }

    pub fn info(&self) -> &VolumeInfo {
        &self.info
    }

    /// Bytes of the header: the data starts at this offset.
    pub fn header_len(&self) -> u64 {
        self.header_len
    }

    /// Appends whole z-slices (x fastest) of data values. Integer types get
    /// the value rounded to the nearest integer and clamped to the type's
    /// limits; NaN and infinities are refused (no reader would accept them).
    pub fn write_slices(&mut self, values: &[f32]) -> Result<()> {
        let label = self.path.display().to_string();
        let slice_len = self.info.slice_len() as u64;
        let n = values.len() as u64;
        ensure!(
            n / slice_len * slice_len == n,
            "{label}: write_slices needs whole slices of {slice_len} values, got {n}"
        );
        ensure!(
            self.written + n <= self.info.voxel_count(),
            "{label}: writing past the end of the volume ({} of {} voxels)",
            self.written + n,
            self.info.voxel_count()
        );
        check_finite(
            &format!("{label}: cannot write"),
            self.info.dims,
            self.written,
            values,
            false,
        )?;
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        encode_samples(values, self.info.voxel_type, false, &mut buf);
        let res = self.out.write_all(&buf);
        self.buf = buf;
        res.with_context(|| format!("{}: writing", self.out.temp_path().display()))?;
        self.written += n;
        Ok(())
    }

    /// Flushes, syncs and renames the file to its final name. Every voxel
    /// must have been written.
    pub fn finish(self) -> Result<()> {
        let label = self.path.display().to_string();
        ensure!(
            self.written == self.info.voxel_count(),
            "{label}: only {} of {} voxels were written",
            self.written,
            self.info.voxel_count()
        );
        self.out.commit()
    }
}
