//! Scalar volumes as the rest of Parallax sees them: a grid of data values with
//! voxel spacing, read slice by slice so that nothing needs the whole volume in
//! memory (docs/design.md "Data").
//!
//! Volume space (docs/design.md conventions): voxel (i, j, k) has its centre at
//! ((i+½)·sx, (j+½)·sy, (k+½)·sz); the volume is the box [0, N·s] on each axis;
//! the field is the trilinear interpolant of the voxel values, clamped to the
//! edge voxels inside the box.

use serde::{Deserialize, Serialize};

/// The sample type of a source volume. Values are always handed on as `f32`
/// data values: exact for 8- and 16-bit integers; 32-bit integers beyond
/// ±2²⁴ and doubles are rounded to the nearest `f32`, and the reader says how
/// many voxels that changed (new variants go last: the `.pxo` header records
/// the type by its index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum VoxelType {
    U8,
    U16,
    I16,
    F32,
    I8,
    I32,
    U32,
    F64,
}

impl VoxelType {
    /// Every sample type.
    pub const ALL: [VoxelType; 8] = [
        VoxelType::U8,
        VoxelType::U16,
        VoxelType::I16,
        VoxelType::F32,
        VoxelType::I8,
        VoxelType::I32,
        VoxelType::U32,
        VoxelType::F64,
    ];

    pub fn bytes(self) -> usize {
        match self {
            VoxelType::U8 | VoxelType::I8 => 1,
            VoxelType::U16 | VoxelType::I16 => 2,
            VoxelType::F32 | VoxelType::I32 | VoxelType::U32 => 4,
            VoxelType::F64 => 8,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            VoxelType::U8 => "u8",
            VoxelType::U16 => "u16",
            VoxelType::I16 => "i16",
            VoxelType::F32 => "f32",
            VoxelType::I8 => "i8",
            VoxelType::I32 => "i32",
            VoxelType::U32 => "u32",
            VoxelType::F64 => "f64",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "u8" | "uint8" => VoxelType::U8,
            "u16" | "uint16" => VoxelType::U16,
            "i16" | "int16" => VoxelType::I16,
            "f32" | "float32" | "float" => VoxelType::F32,
            "i8" | "int8" => VoxelType::I8,
            "i32" | "int32" => VoxelType::I32,
            "u32" | "uint32" => VoxelType::U32,
            "f64" | "float64" | "double" => VoxelType::F64,
            _ => return None,
        })
    }

    /// Smallest and largest representable value (data units).
    pub fn limits(self) -> (f64, f64) {
        match self {
            VoxelType::U8 => (0.0, 255.0),
            VoxelType::U16 => (0.0, 65535.0),
            VoxelType::I16 => (-32768.0, 32767.0),
            VoxelType::F32 | VoxelType::F64 => (f32::MIN as f64, f32::MAX as f64),
            VoxelType::I8 => (-128.0, 127.0),
            VoxelType::I32 => (i32::MIN as f64, i32::MAX as f64),
            VoxelType::U32 => (0.0, u32::MAX as f64),
        }
    }

    /// Floating-point samples (may hold NaN or ±Inf; not integer data).
    pub fn is_float(self) -> bool {
        matches!(self, VoxelType::F32 | VoxelType::F64)
    }

    /// Samples that `f32` cannot always hold exactly.
    pub fn may_round(self) -> bool {
        matches!(self, VoxelType::I32 | VoxelType::U32 | VoxelType::F64)
    }
}

/// What is known about a volume before reading its voxels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VolumeInfo {
    /// Voxels along x, y, z (x varies fastest in memory and on disk).
    pub dims: [usize; 3],
    /// Voxel spacing in the data's length unit (mm for medical data).
    pub spacing: [f64; 3],
    /// Sample type of the source.
    pub voxel_type: VoxelType,
}

/// The extent N·s of `dims` voxels of `spacing` on each axis (data length
/// units): the one computation of a volume's box, for the source volume
/// ([`VolumeInfo::extent`]) and for its octree ([`crate::geometry::Geometry`]).
pub fn extent(dims: [usize; 3], spacing: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|a| dims[a] as f64 * spacing[a])
}

impl VolumeInfo {
    pub fn voxel_count(&self) -> u64 {
        self.dims.iter().map(|&d| d as u64).product()
    }

    pub fn slice_len(&self) -> usize {
        self.dims[0] * self.dims[1]
    }

    /// The volume's extent N·s on each axis (data length units).
    pub fn extent(&self) -> [f64; 3] {
        extent(self.dims, self.spacing)
    }

    /// Bytes of the source data (for throughput and compression ratios).
    pub fn source_bytes(&self) -> u64 {
        self.voxel_count() * self.voxel_type.bytes() as u64
    }
}

/// A volume that is read front to back, a few z-slices at a time.
///
/// Implementations read lazily, in increasing z, and check what they read:
/// a truncated file or a NaN in float input is an error that names the file
/// (and, for NaN, the voxel).
pub trait VolumeSource {
    fn info(&self) -> &VolumeInfo;
    /// Fills `out` (whose length is a whole number of slices, `nx·ny` values
    /// each, x fastest) with the next slices, as data values.
    fn read_slices(&mut self, out: &mut [f32]) -> anyhow::Result<()>;
    /// After reading: what converting the samples to `f32` data values
    /// changed, if anything (32-bit integers beyond ±2²⁴, doubles).
    fn conversion_note(&self) -> Option<String> {
        None
    }
    /// What import records of the source beside its path and tells the
    /// user (a DICOM series' UID and patient orientation, a TIFF stack's
    /// missing spacing), if anything.
    fn describe(&self) -> Option<String> {
        None
    }
    /// Where the volume lies in the scanner's patient space, if the file
    /// says: the affine map from volume space (data units from the first
    /// voxel's corner) to LPS millimetres (`store::Summary::world`).
    fn world(&self) -> Option<[[f64; 4]; 3]> {
        None
    }
    /// NaN in the input means "no data": passed on as NaN instead of
    /// refused (sources whose samples cannot be NaN ignore this).
    fn set_nan_empty(&mut self) {}
    /// Bytes the source itself holds while it is read (an OME-Zarr source's
    /// slab of one row of chunks), counted in the import's memory budget.
    fn buffer_bytes(&self) -> u64 {
        0
    }
    /// The time points the file holds (a 4-D NIfTI's `dim[4]`, an
    /// OME-Zarr image's `t` axis); one is read, chosen by `--time`.
    fn time_points(&self) -> usize {
        1
    }
    /// The coarser resolution levels the file itself holds beside the one
    /// read (an OME-Zarr pyramid), finest first: import takes those that
    /// halve the volume as the octree does instead of averaging its own
    /// (`ImportOptions::pyramid`).
    fn pyramid(&self) -> anyhow::Result<Vec<FileLevel>> {
        Ok(Vec::new())
    }
    /// A source reading the file's level `index` (one of [`pyramid`]'s),
    /// with this source's settings.
    ///
    /// [`pyramid`]: VolumeSource::pyramid
    fn open_level(&self, index: usize) -> anyhow::Result<Box<dyn VolumeSource + Send>> {
        anyhow::bail!("level {index}: this source holds no resolution levels of its own")
    }
}

/// One coarser resolution level of a source file ([`VolumeSource::pyramid`]):
/// its index among the file's levels, and its voxels and their spacing in
/// the units of the level being read.
#[derive(Clone, Debug, PartialEq)]
pub struct FileLevel {
    pub index: usize,
    pub dims: [usize; 3],
    pub spacing: [f64; 3],
}

/// A whole volume in memory: the reference integrator's input and the small
/// volumes of tests. Large volumes go through [`VolumeSource`] instead.
#[derive(Clone, Debug)]
pub struct Volume {
    pub info: VolumeInfo,
    /// `dims[0]·dims[1]·dims[2]` data values, x fastest.
    pub data: Vec<f32>,
}

impl Volume {
    pub fn new(info: VolumeInfo, data: Vec<f32>) -> Self {
        assert_eq!(data.len() as u64, info.voxel_count(), "volume data size");
        Volume { info, data }
    }

    /// Builds a volume from a function of the voxel index.
    pub fn from_fn(
        dims: [usize; 3],
        spacing: [f64; 3],
        voxel_type: VoxelType,
        f: impl Fn(usize, usize, usize) -> f32,
    ) -> Self {
        let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    data.push(f(i, j, k));
                }
            }
        }
        Volume::new(
            VolumeInfo {
                dims,
                spacing,
                voxel_type,
            },
            data,
        )
    }

    /// Reads a whole source into memory.
    pub fn read_all(src: &mut dyn VolumeSource) -> anyhow::Result<Self> {
        let info = src.info().clone();
        let mut data = vec![0.0f32; info.voxel_count() as usize];
        if !data.is_empty() {
            src.read_slices(&mut data)?;
        }
        Ok(Volume { info, data })
    }

    #[inline]
    pub fn voxel(&self, i: usize, j: usize, k: usize) -> f32 {
        let [nx, ny, _] = self.info.dims;
        self.data[(k * ny + j) * nx + i]
    }

    /// The scalar field at a point of volume space: the trilinear interpolant
    /// of the voxel values, clamped to the edge voxels (docs/design.md). Voxels
    /// without data (NaN) are left out: the weights of the others are
    /// renormalised, and where all eight are NaN the result is NaN (no data).
    pub fn sample(&self, p: [f64; 3]) -> f64 {
        let mut i0 = [0usize; 3];
        let mut i1 = [0usize; 3];
        let mut w = [0f64; 3];
        for a in 0..3 {
            let n = self.info.dims[a];
            let u = (p[a] / self.info.spacing[a] - 0.5).clamp(0.0, (n - 1) as f64);
            let f = u.floor();
            i0[a] = f as usize;
            i1[a] = (i0[a] + 1).min(n - 1);
            w[a] = u - f;
        }
        let v = |i: usize, j: usize, k: usize| self.voxel(i, j, k) as f64;
        let corners = [
            v(i0[0], i0[1], i0[2]),
            v(i1[0], i0[1], i0[2]),
            v(i0[0], i1[1], i0[2]),
            v(i1[0], i1[1], i0[2]),
            v(i0[0], i0[1], i1[2]),
            v(i1[0], i0[1], i1[2]),
            v(i0[0], i1[1], i1[2]),
            v(i1[0], i1[1], i1[2]),
        ];
        if corners.iter().any(|c| c.is_nan()) {
            let (mut sum, mut wsum) = (0.0, 0.0);
            for (c, &value) in corners.iter().enumerate() {
                if value.is_nan() {
                    continue;
                }
                let weight = (if c & 1 == 1 { w[0] } else { 1.0 - w[0] })
                    * (if c & 2 == 2 { w[1] } else { 1.0 - w[1] })
                    * (if c & 4 == 4 { w[2] } else { 1.0 - w[2] });
                sum += weight * value;
                wsum += weight;
            }
            return if wsum > 0.0 { sum / wsum } else { f64::NAN };
        }
        let x00 = v(i0[0], i0[1], i0[2]) * (1.0 - w[0]) + v(i1[0], i0[1], i0[2]) * w[0];
        let x10 = v(i0[0], i1[1], i0[2]) * (1.0 - w[0]) + v(i1[0], i1[1], i0[2]) * w[0];
        let x01 = v(i0[0], i0[1], i1[2]) * (1.0 - w[0]) + v(i1[0], i0[1], i1[2]) * w[0];
        let x11 = v(i0[0], i1[1], i1[2]) * (1.0 - w[0]) + v(i1[0], i1[1], i1[2]) * w[0];
        let y0 = x00 * (1.0 - w[1]) + x10 * w[1];
        let y1 = x01 * (1.0 - w[1]) + x11 * w[1];
        y0 * (1.0 - w[2]) + y1 * w[2]
    }

    /// Smallest and largest voxel value.
    pub fn range(&self) -> (f32, f32) {
        self.data
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    }
}

/// An in-memory volume read as a source (tests, and synthetic data).
pub struct MemorySource<'a> {
    volume: &'a Volume,
    next: usize,
}

impl<'a> MemorySource<'a> {
    pub fn new(volume: &'a Volume) -> Self {
        MemorySource { volume, next: 0 }
    }
}

impl VolumeSource for MemorySource<'_> {
    fn info(&self) -> &VolumeInfo {
        &self.volume.info
    }

    fn read_slices(&mut self, out: &mut [f32]) -> anyhow::Result<()> {
        let end = self.next + out.len();
        anyhow::ensure!(
            end <= self.volume.data.len(),
            "read past the end of an in-memory volume"
        );
        out.copy_from_slice(&self.volume.data[self.next..end]);
        self.next = end;
        Ok(())
    }
}
