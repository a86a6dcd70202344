//! The GPU ray caster (`shaders/raycast.wgsl`): renders every view of a frame
//! in one dispatch over one brick pool, one spatial index and one visibility
//! feedback buffer, zeroed once per frame for all views (G10 §5).

pub mod params;
pub mod pool;
pub mod shader;
mod subframes;
pub mod texels;
pub mod tiles;

use crate::gpu::Gpu;
use crate::index::SpatialIndex;
use crate::store::OctreeLayout;
use anyhow::{bail, Result};
use parallax_common::camera::{Placement, View, MAX_FRAME_PIXELS, MAX_VIEW_SIDE};
use parallax_common::config::Preintegration;
use parallax_common::tf::closed::{ClosedForm, GpuPieces, MAX_PIECES};
use parallax_common::tf::{Channel, PreintLayout, PreintTable, TransferFunction};
use parallax_common::tools::{EnhancerKind, MAX_ENHANCERS};
pub use params::ToolParams;
use params::{GpuFrame, GpuView};
pub use pool::BrickPool;
pub use shader::KernelKey;
use std::collections::HashMap;
use wgpu::util::DeviceExt;

/// The pre-integration table on the GPU (G10 §4 Eq. 2).
///
/// Segment integrals over whole bins come from the dyadic sum pyramid
/// (every term ≥ 0, nothing cancels). When the transfer function's dynamic
/// range allows it, a running integral F_j stored as an f32 pair (hi + lo,
/// ≈ 48 significant bits) is added: one difference instead of up to
/// 2·log2 N pyramid reads. Its error, ≈ 2⁻⁴⁸·F_total, is then below 2⁻²⁸ of
/// the smallest non-zero bin — the cancellation G10's single running
/// integral suffers cannot reach a visible size. Extreme ranges (say
/// τ = 1e-6 beside 1e6) keep the pyramid alone.
pub struct TfTable {
    /// The table's entries (WGSL `tf_entry`).
    buffer: texels::TexelTable,
    layout: PreintLayout,
    /// Index (in vec4 entries) of the F_j pairs, 0 when not used.
    prefix_offset: u32,
    /// First entry of the (ι, ν, 0, 0) part and its running integral's.
    aux_base: u32,
    aux_prefix: u32,
    /// ι_max of the transfer function (MImDA's termination estimate).
    max_importance: f32,
    /// Whether the march pre-integrates from the segments' ends
    /// (preint.wgsl `end_average`), and whether the table allows it: a
    /// running integral, and bin integrals within [`END_RANGE`] of each
    /// other in every DVR channel.
    end_path: bool,
    end_allowed: bool,
    /// The 2D table (`preintegration = "2d"`), made when first asked for,
    /// and its nodes per axis.
    grid: Option<(wgpu::Texture, wgpu::TextureView, u32)>,
    /// How many pieces the DVR channels' closed form has
    /// (`preintegration = "analytic"`), where the function has one, and the
    /// uniform the kernel reads them from (zeros without).
    closed_pieces: Option<u32>,
    pieces: wgpu::Buffer,
    /// Which table this is (a bind group names one table).
    id: u64,
}

/// An n × n rgba32float texture for the 2D pre-integration table.
fn grid_descriptor(label: &str, n: u32) -> wgpu::TextureDescriptor<'_> {
    wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: n,
            height: n,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    }
}

/// A process-wide serial number for GPU resources a bind group refers to.
pub(crate) fn next_resource_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// Largest F_total / (smallest non-zero bin) for which the running integral
/// is used.
const PREFIX_RANGE: f64 = (1u64 << 20) as f64;

/// Largest (largest bin integral) / (smallest non-zero one) of a channel for
/// which the march pre-integrates from the segments' ends: its f32 partial
/// bins then err by at most 2⁻²³·2¹² = 2⁻¹¹ of the smallest non-zero bin.
const END_RANGE: f64 = (1u64 << 12) as f64;

/// `x` / (smallest non-zero bin integral of a channel); 1 where `x` is 0.
fn over_smallest_bin(bins: &[f64], x: f64) -> f64 {
    let min = bins
        .iter()
        .cloned()
        .filter(|&x| x > 0.0)
        .fold(f64::INFINITY, f64::min);
    if x > 0.0 {
        x / min
    } else {
        1.0
    }
}

impl TfTable {
    /// The tables of `tf`, `table` its pre-integration table.
    pub fn new(gpu: &Gpu, table: &PreintTable, tf: &TransferFunction) -> Self {
        let max_importance = tf.max_importance();
        let (planar, layout) = table.gpu_layout();
        // Two interleaved parts with the same layout: (τ, k̃r, k̃g, k̃b), what
        // DVR reads, one 16-byte load per table entry; then (ι, ν, 0, 0),
        // read only by the MImDA and refraction kernels.
        let mut data = Vec::new();
        let prefix_offset = Self::push_part(
            &mut data,
            &planar,
            &layout,
            table,
            [
                Some(Channel::Tau),
                Some(Channel::EmissionR),
                Some(Channel::EmissionG),
                Some(Channel::EmissionB),
            ],
        );
        let aux_base = data.len() as u32;
        let aux_prefix = Self::push_part(
            &mut data,
            &planar,
            &layout,
            table,
            [
                Some(Channel::Importance),
                Some(Channel::Refraction),
                None,
                None,
            ],
        );
        let texels: Vec<[u32; 4]> = data.iter().map(|v| v.map(f32::to_bits)).collect();
        let buffer = texels::TexelTable::new(gpu, "pre-integration table", texels.len() as u64);
        buffer.write(gpu, 0, &texels);
        let end_allowed = prefix_offset != 0
            && [
                Channel::Tau,
                Channel::EmissionR,
                Channel::EmissionG,
                Channel::EmissionB,
            ]
            .iter()
            .all(|&ch| {
                let bins = table.level(ch, 0);
                over_smallest_bin(bins, bins.iter().cloned().fold(0.0, f64::max)) <= END_RANGE
            });
        let closed = ClosedForm::new(tf, table.vmin(), table.vmax());
        let uniform: GpuPieces = closed
            .as_ref()
            .map_or([[0.0; 4]; 1 + 4 * MAX_PIECES], |c| c.gpu());
        let pieces = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("transfer function pieces"),
                contents: bytemuck::cast_slice(&uniform),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        TfTable {
            buffer,
            layout,
            prefix_offset,
            end_path: end_allowed,
            end_allowed,
            grid: None,
            closed_pieces: closed.map(|c| c.pieces.len() as u32),
            pieces,
            aux_base,
            aux_prefix,
            max_importance: max_importance as f32,
            id: next_resource_id(),
        }
    }

    /// Appends one part (four channels interleaved, nodes and pyramid) and,
    /// where the channels' range allows, its running integral; returns the
    /// running integral's first entry (0: none).
    fn push_part(
        data: &mut Vec<[f32; 4]>,
        planar: &[f32],
        layout: &PreintLayout,
        table: &PreintTable,
        channels: [Option<Channel>; 4],
    ) -> u32 {
        let stride = layout.channel_stride as usize;
        data.extend((0..stride).map(|i| {
            std::array::from_fn(|c| channels[c].map_or(0.0, |ch| planar[ch.index() * stride + i]))
        }));
        let bins: Vec<&[f64]> = channels
            .iter()
            .map(|c| c.map_or(&[][..], |ch| table.level(ch, 0)))
            .collect();
        let n = table.level(Channel::Tau, 0).len();
        let range = bins
            .iter()
            .map(|b| over_smallest_bin(b, b.iter().sum()))
            .fold(1.0, f64::max);
        if range > PREFIX_RANGE {
            return 0;
        }
        let start = data.len() as u32;
        let mut f = [0f64; 4];
        for j in 0..=n {
            let hi: [f32; 4] = std::array::from_fn(|c| f[c] as f32);
            let lo: [f32; 4] = std::array::from_fn(|c| (f[c] - hi[c] as f64) as f32);
            data.push(hi);
            data.push(lo);
            if j < n {
                for c in 0..4 {
                    f[c] += bins[c].get(j).copied().unwrap_or(0.0);
                }
            }
        }
        start
    }

    /// Whether whole bins are summed by the running integral.
    pub fn uses_running_integral(&self) -> bool {
        self.prefix_offset != 0
    }

    /// Whether the march pre-integrates from the segments' ends (each
    /// sample reads its bin once) rather than per segment.
    pub fn uses_end_path(&self) -> bool {
        self.end_path
    }

    /// Makes the 2D pre-integration table (PreintTable::grid) of `table`,
    /// the table this was made from, on the GPU, once; `preintegration =
    /// "2d"` samples it bilinearly.
    pub fn build_grid(&mut self, gpu: &Gpu, table: &PreintTable) {
        if self.grid.is_some() {
            return;
        }
        let n = table.grid_nodes() as u32;
        let data = table.grid();
        let texture = gpu.device.create_texture_with_data(
            &gpu.queue,
            &grid_descriptor("2D pre-integration table", n),
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&data),
        );
        let view = texture.create_view(&Default::default());
        self.grid = Some((texture, view, n));
        // Bind groups made for this table lack the new texture.
        self.id = next_resource_id();
    }

    /// Whether the DVR channels have a closed form the kernel can use
    /// (`preintegration = "analytic"`; otherwise that falls back to "2d").
    pub fn has_closed_form(&self) -> bool {
        self.closed_pieces.is_some()
    }

    /// Whether `preintegration` reads the 2D table ([`Self::build_grid`]):
    /// "2d", and "analytic" where the function has no closed form.
    pub fn wants_grid(&self, preintegration: Preintegration) -> bool {
        match preintegration {
            Preintegration::TwoD => true,
            Preintegration::Analytic => !self.has_closed_form(),
            Preintegration::Exact => false,
        }
    }

    /// Pre-integrates per segment even where the table allows the end path
    /// (`false`), or from the ends again where it allows it (`true`): the
    /// same integral by another sum, for comparisons.
    pub fn allow_end_path(&mut self, allow: bool) {
        self.end_path = allow && self.end_allowed;
    }
}

/// Quality knobs of the ray caster, and the kernel a frame uses.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Step length as a fraction of the leaf's voxel size.
    pub step_factor: f32,
    /// Rays stop once their opacity reaches this.
    pub early_termination: f32,
    /// Phong shading from central-difference gradients.
    pub shading: bool,
    /// Stepper and enhancer chain (G10 §5: one kernel per combination).
    pub kernel: KernelKey,
    /// MImDA γ (G10 Eq. 3).
    pub gamma: f32,
    /// Isovalue and surface colour (linear RGB) of the isosurface stepper.
    pub iso: [f32; 4],
    /// Render only this quincunx sub-frame (frame reconstruction, G10 §5).
    pub subframe: Option<u32>,
    /// With `subframe`: reconstruct the other pixels on the GPU before the
    /// read-back (`subframes`), first forgetting the history where
    /// `Some(true)`. `None`: the image comes back with the sub-frame's
    /// pixels alone.
    pub reconstruct: Option<bool>,
    /// Prediction buffer (B10 §4): mode (0 off, 1 full traversal, 2
    /// predicted), local window (data units), κ low, κ high.
    pub predict: [f32; 4],
    /// The enhancers' constant parameters, in chain order.
    pub tools: [ToolParams; MAX_ENHANCERS],
    /// Step over empty macrocells (L12 §4.1) where the kernel allows it
    /// (plain DVR: no enhancer, MImDA, refraction or isosurface, which may
    /// act where τ = 0).
    pub macrocells: bool,
    /// Count the samples taken (`Rendered::samples`).
    pub count_samples: bool,
    /// L12's adaptive step (Eq. 3): `step_factor` × 2·t·sin(θ/2), a
    /// fraction of the pixel's footprint at the leaf's distance, instead of
    /// the leaf's voxel.
    pub adaptive_step: bool,
    /// Multilevel sampling (G10 §4, Fig. 5): samples blend the leaf's data
    /// with its parent's and grandparent's as the view's footprint asks,
    /// so a cut that mixes levels shows no seams. `None`: off.
    pub multilevel: Option<Multilevel>,
    /// Tricubic B-spline filtering (L12 §5.1) instead of trilinear.
    pub tricubic: bool,
    /// How segment optics are looked up: the exact table (from the
    /// segments' ends where it allows), the 2D table bilinearly (it must
    /// have been made: [`TfTable::build_grid`]), or in closed form (where
    /// the function has one, [`TfTable::has_closed_form`]; else as "2d").
    pub preintegration: Preintegration,
    /// Run only the 8×8 tiles whose rays can meet data (`tiles`); off,
    /// every tile of every view.
    pub tile_culling: bool,
    /// Fetch each sample one pass of the sample loop ahead (the kernel's
    /// LOOKAHEAD), on pools of float voxels read with the 2D table; the
    /// image is the same bit for bit, off only to show that.
    pub lookahead: bool,
}

/// What multilevel sampling needs to know of refinement: the same footprint
/// and accuracy decide which levels a sample blends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Multilevel {
    /// Refinement's accuracy: a voxel is adequate when it projects to at
    /// most this many pixels.
    pub accuracy: f32,
    /// The light field display whose s(z) sizes the η > 0 views' detail:
    /// s0 (m) and tan(Φ/2).
    pub lightfield: Option<(f32, f32)>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            step_factor: 0.5,
            early_termination: 0.999,
            shading: false,
            kernel: KernelKey::default(),
            gamma: 0.0,
            iso: [0.0; 4],
            subframe: None,
            reconstruct: None,
            predict: [0.0; 4],
            tools: [ToolParams::default(); MAX_ENHANCERS],
            macrocells: true,
            count_samples: false,
            adaptive_step: false,
            multilevel: None,
            tricubic: false,
            preintegration: Preintegration::Exact,
            tile_culling: true,
            lookahead: true,
        }
    }
}

/// Where the volume is and how its octree is shaped.
#[derive(Clone, Copy, Debug)]
pub struct SceneGeometry {
    pub placement: Placement,
    pub layout: OctreeLayout,
    pub spacing: [f64; 3],
}

impl SceneGeometry {
    pub fn extent(&self) -> [f64; 3] {
        std::array::from_fn(|a| self.layout.dims[a] as f64 * self.spacing[a])
    }
}

/// What one frame produced.
pub struct Rendered {
    /// Premultiplied RGBA per view, row 0 at the top.
    pub images: Vec<Vec<[f32; 4]>>,
    /// Per index node: 1 where a leaf with data was traversed.
    pub feedback: Vec<u32>,
    /// Wall time of the GPU work (dispatch to readback).
    pub seconds: f64,
    /// The prediction buffer was asked for but had just been (re)made, so
    /// this frame was a full traversal that fills it.
    pub prediction_reset: bool,
    /// Samples taken (0 unless counted).
    pub samples: u64,
    /// Tiles the dispatch ran.
    pub tiles: u64,
    /// Seconds the CPU took to list them.
    pub tiles_seconds: f64,
}

pub struct Raycaster {
    bind_layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    sampler: wgpu::Sampler,
    hw_filter: bool,
    /// The 2D pre-integration table's sampler (bilinear where the device
    /// filters f32 textures; without that, "2d" falls back to "exact"), and
    /// a 1×1 stand-in bound when a table has none.
    grid_sampler: wgpu::Sampler,
    grid_filterable: bool,
    no_grid: wgpu::TextureView,
    /// One pipeline per combination of stepper, enhancers and shading that
    /// a frame has used (G10 §5: a kernel specialised for what the scene
    /// uses), built when first needed.
    pipelines: HashMap<(KernelKey, [bool; 10], u32), wgpu::ComputePipeline>,
    /// The pool holds f32 values (else 8-bit codes).
    float_pool: bool,
    /// A small uniform buffer for the enhancers' parameters.
    tools: wgpu::Buffer,
    /// The per-frame buffers, kept across frames and grown by capacity.
    frame: FrameBuffers,
    /// Frame reconstruction's filter, made when a frame first asks for it.
    subframes: Option<subframes::SubframeFilter>,
}

/// What one frame renders.
pub struct RenderInputs<'a> {
    pub pool: &'a BrickPool,
    pub index: &'a SpatialIndex,
    pub tf: &'a TfTable,
    pub scene: &'a SceneGeometry,
    pub views: &'a [View],
    pub settings: &'a RenderSettings,
}

/// A buffer reused from frame to frame, replaced by a larger one (by powers
/// of two) only when a frame needs more.
struct Grown {
    buffer: wgpu::Buffer,
    capacity: u64,
}

impl Grown {
    fn new(gpu: &Gpu, label: &'static str, usage: wgpu::BufferUsages, size: u64) -> Self {
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
    fn fit(
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
struct FrameBuffers {
    uniform: wgpu::Buffer,
    /// The views, the spatial index and the tiles the dispatch runs
    /// (`tiles::tiles`), one after the other (`FrameTable`).
    table: texels::TexelTable,
    /// What `table` is copied from each frame, in whole rows.
    table_staging: Grown,
    feedback: Grown,
    image: Grown,
    readback: Grown,
    /// Isosurfaces: each pixel's last hit distance (B10 §4); its contents
    /// mean nothing after it is made or grown.
    prediction: Grown,
    prediction_fresh: bool,
    /// Samples taken this frame, a 64-bit count in two words (counted only
    /// when asked for).
    counters: wgpu::Buffer,
    /// The bind group and the (table, pool) it was made for.
    bind: Option<(wgpu::BindGroup, u64, u64)>,
    /// Buffers made and bind groups made so far (reuse is checked by tests).
    made: FrameBufferCounts,
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
const PREDICTION: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE;
/// Bytes of the sample counters.
const COUNTERS: u64 = 16;
const STAGING: wgpu::BufferUsages =
    wgpu::BufferUsages::COPY_SRC.union(wgpu::BufferUsages::COPY_DST);
const READBACK: wgpu::BufferUsages =
    wgpu::BufferUsages::MAP_READ.union(wgpu::BufferUsages::COPY_DST);

impl FrameBuffers {
    fn new(gpu: &Gpu) -> Self {
        FrameBuffers {
            uniform: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame"),
                size: std::mem::size_of::<GpuFrame>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
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
    fn fit(&mut self, gpu: &Gpu, texels: u64, nodes: u64, image: u64) {
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
struct FrameTable {
    texels: Vec<[u32; 4]>,
    index: u32,
    tiles: u32,
}

fn frame_table(
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

/// How bricks are interpolated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filtering {
    /// By the texture unit (one sample; weights at the hardware's precision).
    Hardware,
    /// By eight loads with exact f32 weights.
    Exact,
}

fn uniform(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn texture(
    binding: u32,
    view_dimension: wgpu::TextureViewDimension,
    filterable: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension,
            multisampled: false,
        },
        count: None,
    }
}

fn sampler(binding: u32, filtering: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Sampler(if filtering {
            wgpu::SamplerBindingType::Filtering
        } else {
            wgpu::SamplerBindingType::NonFiltering
        }),
        count: None,
    }
}

/// A clamping sampler, bilinear or nearest.
fn make_sampler(gpu: &Gpu, label: &str, linear: bool) -> wgpu::Sampler {
    let filter = if linear {
        wgpu::FilterMode::Linear
    } else {
        wgpu::FilterMode::Nearest
    };
    gpu.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some(label),
        mag_filter: filter,
        min_filter: filter,
        ..Default::default()
    })
}

impl Raycaster {
    /// A ray caster for pools of `float` (r32float) or 8-bit bricks. Asked
    /// for hardware filtering of a format the device cannot filter, it
    /// falls back to exact filtering.
    pub fn new(gpu: &Gpu, float_pool: bool, filtering: Filtering) -> Result<Self> {
        let hw_filter = filtering == Filtering::Hardware
            && (!float_pool
                || gpu
                    .device
                    .features()
                    .contains(wgpu::Features::FLOAT32_FILTERABLE));
        let grid_filterable = gpu
            .device
            .features()
            .contains(wgpu::Features::FLOAT32_FILTERABLE);
        let bind_layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("raycast"),
                entries: &[
                    uniform(0),
                    texels::layout_entry(1),
                    texture(3, wgpu::TextureViewDimension::D3, hw_filter),
                    texels::layout_entry(4),
                    texels::layout_entry(5),
                    storage(6, false),
                    storage(7, false),
                    sampler(8, hw_filter),
                    uniform(9),
                    storage(10, false),
                    storage(11, false),
                    texture(12, wgpu::TextureViewDimension::D2, grid_filterable),
                    sampler(13, grid_filterable),
                    uniform(14),
                ],
            });
        let grid_sampler = make_sampler(gpu, "2D pre-integration table", grid_filterable);
        let no_grid = gpu
            .device
            .create_texture(&grid_descriptor("no 2D pre-integration table", 1))
            .create_view(&Default::default());
        let sampler = make_sampler(gpu, "brick pool", hw_filter);
        let pipeline_layout = gpu
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("raycast"),
                bind_group_layouts: &[Some(&bind_layout)],
                immediate_size: 0,
            });
        let tools = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tool parameters"),
            size: std::mem::size_of::<[ToolParams; MAX_ENHANCERS]>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Raycaster {
            bind_layout,
            pipeline_layout,
            sampler,
            hw_filter,
            grid_sampler,
            grid_filterable,
            no_grid,
            pipelines: HashMap::new(),
            float_pool,
            tools,
            frame: FrameBuffers::new(gpu),
            subframes: None,
        })
    }

    /// Whether bricks are filtered by the texture unit.
    pub fn hardware_filtering(&self) -> bool {
        self.hw_filter
    }

    /// The pipeline of a kernel combination, built on first use.
    fn pipeline(
        &mut self,
        gpu: &Gpu,
        kernel: &KernelKey,
        flags: [bool; 10],
        tf_pieces: u32,
    ) -> Result<&wgpu::ComputePipeline> {
        let [shading, no_data, macrocells, count, multilevel, tricubic, end_preint, grid_preint, analytic_preint, lookahead] =
            flags;
        let key = (kernel.clone(), flags, tf_pieces);
        if !self.pipelines.contains_key(&key) {
            let source = shader::kernel(kernel)?;
            let module = gpu.validated("shaders/raycast.wgsl", || {
                gpu.device
                    .create_shader_module(wgpu::ShaderModuleDescriptor {
                        label: Some("raycast.wgsl"),
                        source: wgpu::ShaderSource::Wgsl(source.into()),
                    })
            })?;
            let flag = |b: bool| if b { 1.0 } else { 0.0 };
            let constants = [
                ("SHADING", flag(shading)),
                // Hardware filtering would blend the no-data value in.
                ("HW_FILTER", flag(self.hw_filter && !no_data)),
                ("NO_DATA", flag(no_data)),
                ("MACROCELLS", flag(macrocells)),
                ("COUNT_SAMPLES", flag(count)),
                ("MULTILEVEL", flag(multilevel)),
                ("TRICUBIC", flag(tricubic)),
                ("END_PREINT", flag(end_preint)),
                ("GRID_PREINT", flag(grid_preint)),
                ("ANALYTIC_PREINT", flag(analytic_preint)),
                // The closed form's pieces: a constant, so that their loop
                // unrolls (a pipeline per count, at most 17).
                ("TF_PIECES", tf_pieces as f64),
                // Sample values fetched one pass ahead (the kernel's
                // LOOKAHEAD): set for float pools read with the 2D table,
                // where the pool's wait for memory overlaps the table's
                // fetch, or with the closed form, where it overlaps the
                // arithmetic (docs/figures.md).
                ("LOOKAHEAD", flag(lookahead)),
                // A tap at or above this is a no-data voxel: the top code of
                // an 8-bit pool, NO_DATA_VALUE in a float pool.
                (
                    "NO_DATA_TAP",
                    if self.float_pool {
                        1.0e38
                    } else {
                        254.5 / 255.0
                    },
                ),
            ];
            let p = gpu.validated("ray casting pipeline", || {
                gpu.device
                    .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some("raycast"),
                        layout: Some(&self.pipeline_layout),
                        module: &module,
                        entry_point: Some("main"),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: &constants,
                            ..Default::default()
                        },
                        cache: None,
                    })
            })?;
            self.pipelines.insert(key.clone(), p);
        }
        Ok(&self.pipelines[&key])
    }

    /// Pipelines built so far (one per combination used).
    pub fn pipeline_count(&self) -> usize {
        self.pipelines.len()
    }

    /// Per-frame buffers and bind groups made so far.
    pub fn frame_buffer_counts(&self) -> FrameBufferCounts {
        self.frame.made
    }

    /// Renders all views of a frame.
    pub fn render(&mut self, gpu: &Gpu, inputs: &RenderInputs) -> Result<Rendered> {
        let RenderInputs {
            pool,
            index,
            tf,
            scene,
            views,
            settings,
        } = *inputs;
        let start = std::time::Instant::now();
        if index.is_empty() {
            bail!("render: empty spatial index");
        }
        let mut gviews = Vec::with_capacity(views.len());
        let mut pixels = 0u64;
        for v in views {
            let [w, h] = v.resolution;
            if w > MAX_VIEW_SIDE || h > MAX_VIEW_SIDE {
                bail!("render: a {w}×{h} view exceeds {MAX_VIEW_SIDE} pixels per side");
            }
            gviews.push(GpuView {
                region: v.region.map(|x| x as f32),
                eye: [
                    v.eye[0] as f32,
                    v.eye[1] as f32,
                    v.eye[2] as f32,
                    v.eta as f32,
                ],
                observer: [
                    v.observer[0] as f32,
                    v.observer[1] as f32,
                    v.observer[2] as f32,
                    0.0,
                ],
                size: [w, h, pixels as u32, settings.subframe.map_or(0, |k| k + 1)],
            });
            pixels += w as u64 * h as u64;
            if pixels > MAX_FRAME_PIXELS {
                bail!("render: the views of one frame have more than {MAX_FRAME_PIXELS} pixels together");
            }
        }
        let mut images: Vec<Vec<[f32; 4]>> = views.iter().map(|_| Vec::new()).collect();
        if pixels == 0 {
            return Ok(Rendered {
                images,
                feedback: vec![0; index.len()],
                seconds: 0.0,
                prediction_reset: false,
                samples: 0,
                tiles: 0,
                tiles_seconds: 0.0,
            });
        }
        let mut frame = self.frame_uniform(pool, tf, scene, settings);
        let dev = &gpu.device;
        let fb_size = index.len() as u64 * 4;
        let img_size = pixels * 16;
        if img_size > dev.limits().max_storage_buffer_binding_size {
            bail!("render: {pixels} pixels in one frame exceed the GPU's storage binding limit");
        }
        let k = &settings.kernel;
        let plain = !k.mimda
            && !k.refraction
            && !k.iso
            && k.enhancers.iter().all(|&e| e == EnhancerKind::PassThrough);
        let macrocells = settings.macrocells && plain && pool.cells.per_axis > 0;
        // A plain kernel adds nothing where a ray meets no leaf with data;
        // the others (enhancers that draw on every ray, refraction) need
        // every ray through the volume's box.
        // Multilevel sampling blends a leaf's parent and grandparent into its
        // samples, so its own empty cells do not bound what a ray meets
        // there: leaves, not cells.
        let multilevel = settings.multilevel.is_some() && !k.iso;
        let cull = match (plain, macrocells && !multilevel) {
            _ if !settings.tile_culling => tiles::Cull::Off,
            (false, _) => tiles::Cull::Volume,
            (true, false) => tiles::Cull::Leaves,
            (true, true) => tiles::Cull::Cells(&pool.cells),
        };
        let tiles_start = std::time::Instant::now();
        let tiles = tiles::tiles(views, scene, index, cull, settings.subframe.is_some());
        let tiles_seconds = tiles_start.elapsed().as_secs_f64();
        let table = frame_table(&gviews, index, pool, &tiles);
        let most = texels::ROW as u64 * dev.limits().max_texture_dimension_2d as u64;
        if table.texels.len() as u64 > most {
            bail!(
                "render: the frame's views, index and tiles need {} texels; the GPU's largest table holds {most}",
                table.texels.len()
            );
        }
        frame.dispatch = [tiles.len() as u32, table.index, table.tiles, 0];
        self.frame
            .fit(gpu, table.texels.len() as u64, index.len() as u64, img_size);
        // A prediction buffer just made holds nothing: traverse fully.
        let mut prediction_reset = false;
        if frame.predict[0] > 0.0 && self.frame.prediction_fresh {
            prediction_reset = frame.predict[0] > 1.5;
            frame.predict[0] = 1.0;
            self.frame.prediction_fresh = false;
        }
        let fr = &self.frame;
        gpu.queue
            .write_buffer(&fr.uniform, 0, bytemuck::bytes_of(&frame));
        let mut texels = table.texels;
        let rows = texels.len().div_ceil(texels::ROW as usize);
        texels.resize(rows * texels::ROW as usize, [0; 4]);
        gpu.queue
            .write_buffer(&fr.table_staging.buffer, 0, bytemuck::cast_slice(&texels));
        if !matches!(&fr.bind, Some((_, t, p)) if *t == tf.id && *p == pool.id) {
            let bind = dev.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("raycast"),
                layout: &self.bind_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: fr.uniform.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&fr.table.view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&pool.view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::TextureView(&pool.slots.view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: wgpu::BindingResource::TextureView(&tf.buffer.view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 6,
                        resource: fr.feedback.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 7,
                        resource: fr.image.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 8,
                        resource: wgpu::BindingResource::Sampler(&self.sampler),
                    },
                    wgpu::BindGroupEntry {
                        binding: 9,
                        resource: self.tools.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 10,
                        resource: fr.prediction.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 11,
                        resource: fr.counters.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 12,
                        resource: wgpu::BindingResource::TextureView(
                            tf.grid.as_ref().map_or(&self.no_grid, |g| &g.1),
                        ),
                    },
                    wgpu::BindGroupEntry {
                        binding: 13,
                        resource: wgpu::BindingResource::Sampler(&self.grid_sampler),
                    },
                    wgpu::BindGroupEntry {
                        binding: 14,
                        resource: tf.pieces.as_entire_binding(),
                    },
                ],
            });
            self.frame.bind = Some((bind, tf.id, pool.id));
            self.frame.made.bind_groups += 1;
        }
        gpu.queue
            .write_buffer(&self.tools, 0, bytemuck::cast_slice(&settings.tools));
        // The closed form's pieces where the kernel uses it, else the 2D
        // table where asked for and filterable, else the exact table.
        let closed_pieces = tf
            .closed_pieces
            .filter(|_| settings.preintegration == Preintegration::Analytic && !k.iso);
        let closed = closed_pieces.is_some();
        let grid = tf.wants_grid(settings.preintegration)
            && self.grid_filterable
            && !k.iso
            && tf.grid.is_some();
        let pipeline = self
            .pipeline(
                gpu,
                &settings.kernel,
                [
                    settings.shading,
                    pool.no_data,
                    macrocells,
                    settings.count_samples,
                    settings.multilevel.is_some() && !k.iso,
                    settings.tricubic,
                    tf.end_path && !grid && !closed,
                    grid,
                    closed,
                    settings.lookahead && self.float_pool && (grid || closed),
                ],
                closed_pieces.unwrap_or(0),
            )?
            .clone();
        let fr = &self.frame;
        let bind = &fr.bind.as_ref().expect("made above").0;
        let mut enc = dev.create_command_encoder(&Default::default());
        fr.table
            .copy_rows(&mut enc, &fr.table_staging.buffer, rows as u32);
        // One zeroing per frame for all views (G10 §5).
        enc.clear_buffer(&fr.feedback.buffer, 0, Some(fb_size));
        if settings.count_samples {
            enc.clear_buffer(&fr.counters, 0, None);
        }
        // Pixels of the tiles left out stay zero.
        enc.clear_buffer(&fr.image.buffer, 0, Some(img_size));
        if !tiles.is_empty() {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, bind, &[]);
            let n = tiles.len() as u32;
            pass.dispatch_workgroups(
                n.min(tiles::TILES_PER_ROW),
                n.div_ceil(tiles::TILES_PER_ROW),
                1,
            );
        }
        if let (Some(k), Some(reset)) = (settings.subframe, settings.reconstruct) {
            let filter = match &mut self.subframes {
                Some(f) => f,
                None => self.subframes.insert(subframes::SubframeFilter::new(gpu)?),
            };
            let sizes: Vec<[u32; 2]> = views.iter().map(|v| v.resolution).collect();
            // The image buffer's generation: the count of buffers made
            // changes whenever it is replaced.
            filter.encode(
                gpu,
                &mut enc,
                &fr.image.buffer,
                fr.made.buffers,
                &sizes,
                k,
                reset,
            );
        }
        enc.copy_buffer_to_buffer(&fr.image.buffer, 0, &fr.readback.buffer, 0, img_size);
        enc.copy_buffer_to_buffer(
            &fr.feedback.buffer,
            0,
            &fr.readback.buffer,
            img_size,
            fb_size,
        );
        enc.copy_buffer_to_buffer(
            &fr.counters,
            0,
            &fr.readback.buffer,
            img_size + fb_size,
            COUNTERS,
        );
        gpu.queue.submit([enc.finish()]);
        let readback = &fr.readback.buffer;
        let slice = readback.slice(..img_size + fb_size + COUNTERS);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        gpu.wait()?;
        rx.recv()??;
        {
            let data = slice
                .get_mapped_range()
                .map_err(|e| anyhow::anyhow!("reading back the frame: {e:?}"))?;
            let px: &[[f32; 4]] = bytemuck::cast_slice(&data[..img_size as usize]);
            for (img, v) in images.iter_mut().zip(&gviews) {
                let (off, n) = (v.size[2] as usize, (v.size[0] * v.size[1]) as usize);
                *img = px[off..off + n].to_vec();
            }
            let feedback =
                bytemuck::cast_slice(&data[img_size as usize..(img_size + fb_size) as usize])
                    .to_vec();
            let c: &[u32] = bytemuck::cast_slice(
                &data[(img_size + fb_size) as usize..(img_size + fb_size + COUNTERS) as usize],
            );
            let samples = if settings.count_samples {
                c[0] as u64 | (c[1] as u64) << 32
            } else {
                0
            };
            drop(data);
            readback.unmap();
            Ok(Rendered {
                images,
                feedback,
                seconds: start.elapsed().as_secs_f64(),
                prediction_reset,
                samples,
                tiles: tiles.len() as u64,
                tiles_seconds,
            })
        }
    }

    fn frame_uniform(
        &self,
        pool: &BrickPool,
        tf: &TfTable,
        scene: &SceneGeometry,
        s: &RenderSettings,
    ) -> GpuFrame {
        let ext = scene.extent();
        let pl = &scene.placement;
        let rt = pl.rotation().transpose();
        let col = |c: glam::DVec3| [c.x as f32, c.y as f32, c.z as f32, 0.0];
        let l = &scene.layout;
        let root = l.root_voxels().map(|v| v as f64);
        let sp = scene.spacing;
        let mut tf_offsets = [[0u32; 4]; 8];
        for (k, &o) in tf.layout.level_offsets.iter().enumerate() {
            tf_offsets[k / 4][k % 4] = o;
        }
        GpuFrame {
            rt0: col(rt.x_axis),
            rt1: col(rt.y_axis),
            rt2: col(rt.z_axis),
            center: [
                pl.center[0] as f32,
                pl.center[1] as f32,
                pl.center[2] as f32,
                (1.0 / pl.scale(ext)) as f32,
            ],
            extent: [ext[0] as f32, ext[1] as f32, ext[2] as f32, 0.0],
            domain: [
                (root[0] * sp[0]) as f32,
                (root[1] * sp[1]) as f32,
                (root[2] * sp[2]) as f32,
                0.0,
            ],
            spacing: [
                sp[0] as f32,
                sp[1] as f32,
                sp[2] as f32,
                sp.iter().cloned().fold(f64::INFINITY, f64::min) as f32,
            ],
            tf: [
                tf.layout.vmin as f32,
                tf.layout.bin_width as f32,
                tf.layout.n_bins as f32,
                tf.grid.as_ref().map_or(0.0, |g| g.2 as f32),
            ],
            render: [
                s.step_factor,
                s.early_termination,
                (0.01 / root.iter().cloned().fold(0.0, f64::max)) as f32,
                if s.adaptive_step { 1.0 } else { 0.0 },
            ],
            light: [0.35, 0.65, 0.25, 24.0],
            counts: [
                l.brick as u32,
                l.leaf_level(),
                tf.layout.levels,
                tf.prefix_offset,
            ],
            pool: [pool.grid[0], pool.grid[1], pool.grid[2], pool.side],
            optics: [s.gamma, tf.max_importance, 0.0, 0.0],
            aux: [
                tf.aux_base,
                tf.aux_prefix,
                pool.cells.per_axis,
                pool.cells.voxels,
            ],
            iso: s.iso,
            predict: s.predict,
            tf_offsets,
            tf_mids: [tf.layout.mid_offset, 0, 0, 0],
            lod: match s.multilevel {
                None => [0.0; 4],
                Some(m) => {
                    let (s0, tan_half) = m.lightfield.unwrap_or((0.0, 0.0));
                    let lf = if m.lightfield.is_some() { 1.0 } else { 0.0 };
                    [m.accuracy, s0, tan_half, lf]
                }
            },
            splits: [l.splits[0], l.splits[1], l.splits[2], 0],
            dispatch: [0; 4],
            recip: {
                let t = |k: usize| 1.0 / (pool.grid[k] * pool.side) as f32;
                [t(0), t(1), t(2), (1.0 / tf.layout.bin_width) as f32]
            },
            grid: {
                let n = tf.grid.as_ref().map_or(0.0, |g| g.2 as f32);
                [
                    (n - 1.0) / tf.layout.n_bins as f32 / tf.layout.bin_width as f32,
                    n - 1.0,
                    1.0 / n.max(1.0),
                    0.0,
                ]
            },
        }
    }
}
