//! The per-frame GPU buffers, kept across frames and grown by capacity, and
//! the frame table the kernel reads its views, index and tiles from.

use super::params::{GpuFrame, GpuView};
use super::pool::BrickPool;
use super::texels;
use crate::gpu::Gpu;
use crate::index::SpatialIndex;

/// A buffer reused from frame to frame, replaced by a larger one (by powers
/// of two) only when a frame needs more.
pub(super) struct Grown {
    pub(super) buffer: wgpu::Buffer,
    pub(super) capacity: u64,
}

impl Grown {
    pub(super) fn new(
        gpu: &Gpu,
        label: &'static str,
        usage: wgpu::BufferUsages,
        size: u64,
    ) -> Self {
        let capacity = size.max(256).next_power_of_two();
        Grown {
            buffer: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: capacity,
                usage,
                mapped_at_creation: false,
            }),
            capacity,
        }
    }

    /// Makes room for `size` bytes; true if the buffer was replaced.
    pub(super) fn fit(
        &mut self,
        gpu: &Gpu,
        label: &'static str,
        usage: wgpu::BufferUsages,
        size: u64,
    ) -> bool {
        if size <= self.capacity {
            return false;
        }
        *self = Grown::new(gpu, label, usage, size);
        true
    }
}

/// Frame, views, index, feedback, image and readback buffers, and the bind
/// group over them, rebuilt only when a buffer grows or the transfer
/// function's table or the brick pool is another one.
pub(super) struct FrameBuffers {
    pub(super) constants: wgpu::Buffer,
    /// The views, the spatial index and the tiles the dispatch runs
    /// (`tiles::tiles`), one after the other (`FrameTable`).
    pub(super) table: texels::TexelTable,
    /// What `table` is copied from each frame, in whole rows.
    pub(super) table_staging: Grown,
    pub(super) feedback: Grown,
    pub(super) image: Grown,
    pub(super) readback: Grown,
    /// Isosurfaces: each pixel's last hit distance (B10 §4); its contents
    /// mean nothing after it is made or grown.
    pub(super) prediction: Grown,
    pub(super) prediction_fresh: bool,
    /// Samples taken this frame, a 64-bit count in two words (counted only
    /// when asked for).
    pub(super) counters: wgpu::Buffer,
    /// The bind group and the (table, pool) it was made for.
    pub(super) bind: Option<(wgpu::BindGroup, u64, u64)>,
    /// Buffers made and bind groups made so far (reuse is checked by tests).
    pub(super) made: FrameBufferCounts,
}

/// How often the per-frame GPU objects were made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameBufferCounts {
    pub buffers: u64,
    pub bind_groups: u64,
}

const FEEDBACK: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);
const IMAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);
// Cleared each frame when it records depths (`RenderSettings::record_depth`).
const PREDICTION: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);
/// Bytes of the sample counters.
pub(super) const COUNTERS: u64 = 16;
const STAGING: wgpu::BufferUsages =
    wgpu::BufferUsages::COPY_SRC.union(wgpu::BufferUsages::COPY_DST);
const READBACK: wgpu::BufferUsages =
    wgpu::BufferUsages::MAP_READ.union(wgpu::BufferUsages::COPY_DST);

impl FrameBuffers {
    pub(super) fn new(gpu: &Gpu) -> Self {
        FrameBuffers {
            constants: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame"),
                size: std::mem::size_of::<GpuFrame>() as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            table: texels::TexelTable::new(gpu, "views, spatial index and tiles", 0),
            table_staging: Grown::new(gpu, "views, spatial index and tiles (staging)", STAGING, 0),
            feedback: Grown::new(gpu, "visibility feedback", FEEDBACK, 0),
            image: Grown::new(gpu, "image", IMAGE, 0),
            readback: Grown::new(gpu, "readback", READBACK, 0),
            prediction: Grown::new(gpu, "prediction buffer", PREDICTION, 0),
            prediction_fresh: true,
            counters: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("sample counters"),
                size: COUNTERS,
                usage: FEEDBACK,
                mapped_at_creation: false,
            }),
            bind: None,
            made: FrameBufferCounts {
                buffers: 8,
                bind_groups: 0,
            },
        }
    }

    /// Grows what this frame needs; drops the bind group if anything it
    /// names changed.
    pub(super) fn fit(&mut self, gpu: &Gpu, texels: u64, nodes: u64, image: u64) {
        let feedback = nodes * 4;
        let grown = [
            self.table.fit(gpu, texels),
            self.feedback
                .fit(gpu, "visibility feedback", FEEDBACK, feedback),
            self.image.fit(gpu, "image", IMAGE, image),
            self.prediction
                .fit(gpu, "prediction buffer", PREDICTION, image / 4),
        ];
        self.prediction_fresh |= grown[3];
        let staging = self.table_staging.fit(
            gpu,
            "views, spatial index and tiles (staging)",
            STAGING,
            self.table.capacity() * 16,
        );
        let readback = self
            .readback
            .fit(gpu, "readback", READBACK, image + feedback + COUNTERS);
        self.made.buffers +=
            grown.iter().filter(|&&g| g).count() as u64 + readback as u64 + staging as u64;
        if grown.contains(&true) {
            self.bind = None;
        }
    }
}

/// The views, index nodes and tiles of a frame as the kernel reads them
/// (WGSL `view_at`, `node_at`, `tile_at`): each view in 4 texels from
/// texel 0, each node in 2 from `index` (with its slot's data values:
/// entering a leaf reads no slot texel), two tiles a texel from `tiles`.
pub(super) struct FrameTable {
    pub(super) texels: Vec<[u32; 4]>,
    pub(super) index: u32,
    pub(super) tiles: u32,
}

pub(super) fn frame_table(
    views: &[GpuView],
    index: &SpatialIndex,
    pool: &BrickPool,
    tiles: &[[u32; 2]],
) -> FrameTable {
    let mut texels = Vec::with_capacity(4 * views.len() + 2 * index.len() + tiles.len() / 2 + 1);
    let bits = |v: [f32; 4]| v.map(f32::to_bits);
    for v in views {
        texels.extend([bits(v.region), bits(v.eye), bits(v.observer), v.size]);
    }
    let first_node = texels.len() as u32;
    for n in &index.nodes {
        texels.push([n.tree, n.data, n.range, n.nx]);
        let [lo, span] = n
            .slot()
            .and_then(|s| pool.values.get(s as usize))
            .map_or([0; 2], |v| v.map(f32::to_bits));
        texels.push([n.ny, n.nz, lo, span]);
    }
    let first_tile = texels.len() as u32;
    for pair in tiles.chunks(2) {
        let second = pair.get(1).copied().unwrap_or([0; 2]);
        texels.push([pair[0][0], pair[0][1], second[0], second[1]]);
    }
    FrameTable {
        texels,
        index: first_node,
        tiles: first_tile,
    }
}
