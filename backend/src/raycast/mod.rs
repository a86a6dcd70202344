//! The GPU ray caster (`shaders/raycast.wgsl`): renders every view of a frame
//! in one dispatch over one brick pool, one spatial index and one visibility
//! feedback buffer, zeroed once per frame for all views (G10 §5).

mod bindings;
mod constants;
mod frame;
pub mod params;
mod pipeline;
pub mod pool;
mod settings;
pub mod shader;
mod subframes;
pub mod texels;
mod tf_table;
pub mod tiles;

pub use crate::geometry::SceneGeometry;
use crate::gpu::Gpu;
use crate::index::SpatialIndex;
use anyhow::{bail, Result};
pub use frame::FrameBufferCounts;
use frame::{FrameBuffers, Grown, COUNTERS};
use parallax_common::camera::{View, MAX_FRAME_PIXELS, MAX_VIEW_SIDE};
use parallax_common::config::Preintegration;
use parallax_common::tools::MAX_ENHANCERS;
use params::GpuView;
pub use params::ToolParams;
pub use pool::BrickPool;
pub use settings::{Filtering, Multilevel, RenderSettings};
pub use shader::KernelKey;
use std::collections::HashMap;
pub use tf_table::TfTable;

/// A process-wide serial number for GPU resources a bind group refers to.
pub(crate) fn next_resource_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
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
    pipelines: HashMap<(KernelKey, [bool; 12], u32), wgpu::ComputePipeline>,
    /// The pool holds f32 values (else 8-bit codes).
    float_pool: bool,
    /// A small uniform buffer for the enhancers' parameters.
    tools: wgpu::Buffer,
    /// The registered layers' parameters (`LayerParams`).
    layers: wgpu::Buffer,
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

/// Whether a segment of this frame can have an optical depth above 1, the
/// opaque-segment refinement's threshold (`refinement`): the transfer
/// function's largest extinction over the longest step of the cut's
/// coarsest leaf with data (`step_factor` × its voxel along the frame's
/// rays, bounded by [`longest_voxel_along`]; any step with the adaptive
/// one). Where it cannot, the kernel leaves the refinement out and costs
/// what it did without it.
fn can_be_opaque(
    index: &SpatialIndex,
    scene: &SceneGeometry,
    views: &[View],
    max_extinction: f32,
    settings: &RenderSettings,
) -> bool {
    if max_extinction <= 0.0 {
        return false;
    }
    if settings.adaptive_step {
        return true;
    }
    let Some(coarsest) = index
        .nodes
        .iter()
        .filter(|n| n.slot().is_some() && n.first_child().is_none())
        .map(|n| n.level())
        .min()
    else {
        return false;
    };
    let scale = scene.geom.layout.voxel_scale(coarsest);
    let edges: [f64; 3] = std::array::from_fn(|a| scale[a] as f64 * scene.geom.spacing[a]);
    let voxel = longest_voxel_along(views, &scene.placement, edges);
    f64::from(max_extinction) * f64::from(settings.step_factor) * voxel > REFINE_DEPTH
}

/// An upper bound on a voxel of `edges` measured along any ray of `views`
/// (the kernel's `voxel_along`, 1 / |d ⊘ e|): the longest edge, unless the
/// rays keep away from its axis. Each view's rays start on the segment of
/// G10 Eq. 1's origins (a point for η = 0) and end in its screen region, so
/// their directions lie in the convex cone of the eight directions from
/// that segment's ends to the region's corners, and in the circular cone
/// around their mean that holds all eight (if narrower than a half space).
/// A direction at least θ from the longest edge's axis has d_l² ≤ cos²θ,
/// so |d ⊘ e|² ≥ sin²θ / m² + cos²θ / l² (l the longest edge, m the next):
/// on thick slices seen across, the step is the in-plane voxel's, not the
/// slice's.
fn longest_voxel_along(
    views: &[View],
    placement: &parallax_common::camera::Placement,
    edges: [f64; 3],
) -> f64 {
    use glam::DVec3;
    let longest = edges.iter().cloned().fold(0.0, f64::max);
    let axis = (0..3).fold(0, |b, a| if edges[a] > edges[b] { a } else { b });
    let next = (0..3)
        .filter(|&a| a != axis)
        .map(|a| edges[a])
        .fold(0.0, f64::max);
    if !(next > 0.0 && next < longest) {
        return longest;
    }
    let rt = placement.rotation().transpose();
    let mut bound: f64 = 0.0;
    for v in views {
        let [x0, y0, w, h] = v.region;
        let corners = [
            DVec3::new(x0, y0, 0.0),
            DVec3::new(x0 + w, y0, 0.0),
            DVec3::new(x0, y0 + h, 0.0),
            DVec3::new(x0 + w, y0 + h, 0.0),
        ];
        let (e, o) = (DVec3::from(v.eye), DVec3::from(v.observer));
        // The origins' segment: O.x from the region's left and right edge
        // (View::ray; the same point where η = 0 or the eye is on the screen).
        let origin = |x: f64| {
            let dz = -e.z;
            let mcop = if dz.abs() > 1e-12 {
                e.x + (x - e.x) / dz * (o.z - e.z)
            } else {
                o.x
            };
            DVec3::new((1.0 - v.eta) * o.x + v.eta * mcop, o.y, o.z)
        };
        let mut dirs = Vec::with_capacity(8);
        for start in [origin(x0), origin(x0 + w)] {
            for c in corners {
                let d = rt * (c - start);
                if !d.is_finite() || d.length() <= 0.0 {
                    return longest;
                }
                dirs.push(d.normalize());
            }
        }
        let mean = dirs.iter().fold(DVec3::ZERO, |m, d| m + *d);
        if !mean.is_finite() || mean.length() <= 1e-9 {
            return longest;
        }
        let mean = mean.normalize();
        let half = dirs
            .iter()
            .map(|d| d.dot(mean).clamp(-1.0, 1.0).acos())
            .fold(0.0, f64::max);
        if half >= std::f64::consts::FRAC_PI_2 {
            return longest;
        }
        let to_axis = mean[axis].abs().clamp(0.0, 1.0).acos();
        let theta = (to_axis - half).max(0.0);
        let (s, c) = theta.sin_cos();
        let q = s * s / (next * next) + c * c / (longest * longest);
        bound = bound.max((1.0 / q.sqrt()).min(longest));
    }
    if views.is_empty() {
        longest
    } else {
        bound
    }
}

/// The optical depth above which a segment is refined (the kernel's
/// REFINE_DEPTH, a pipeline constant set from this); also where the loader
/// holds a voxel to be opaque (`LoaderConfig::opaque_detail`).
pub(crate) const REFINE_DEPTH: f64 = 1.0;

impl Raycaster {
    /// A ray caster for pools of `float` (r32float) or 8-bit bricks. Asked
    /// for hardware filtering of a format the device cannot filter, it
    /// falls back to exact filtering.
    pub fn new(gpu: &Gpu, float_pool: bool, filtering: Filtering) -> Result<Self> {
        let grid_filterable = gpu
            .device
            .features()
            .contains(wgpu::Features::FLOAT32_FILTERABLE);
        let hw_filter = filtering == Filtering::Hardware && (!float_pool || grid_filterable);
        let bind_layout = bindings::layout(gpu, hw_filter, grid_filterable);
        let grid_sampler = bindings::make_sampler(gpu, "2D pre-integration table", grid_filterable);
        let no_grid = gpu
            .device
            .create_texture(&tf_table::grid_descriptor("no 2D pre-integration table", 1))
            .create_view(&Default::default());
        let sampler = bindings::make_sampler(gpu, "brick pool", hw_filter);
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
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layers = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("layer parameters"),
            size: std::mem::size_of::<[params::LayerParams; parallax_common::config::MAX_LAYERS]>()
                as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Raycaster {
            layers,
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

    /// Pipelines built so far (one per combination used).
    pub fn pipeline_count(&self) -> usize {
        self.pipelines.len()
    }

    /// The buffer that holds the last frame's pixels, every view's after
    /// the one before (premultiplied linear RGBA, row 0 at the top): what
    /// `--present` shows without reading it back.
    pub fn image_buffer(&self) -> &wgpu::Buffer {
        &self.frame.image.buffer
    }

    /// Each pixel's depth where the frame recorded it
    /// (`RenderSettings::record_depth`; the prediction buffer, which the
    /// isosurface fills with its hits), in the views' order.
    pub fn depth_buffer(&self) -> &wgpu::Buffer {
        &self.frame.prediction.buffer
    }

    /// Per-frame buffers and bind groups made so far.
    pub fn frame_buffer_counts(&self) -> FrameBufferCounts {
        self.frame.made
    }

    /// Renders all views of a frame, in G10's stages: each pixel's ray
    /// (Eq. 1), the tiles whose rays can meet data, the frame's constants
    /// and tables, the kernel specialised for the scene (§5), one dispatch
    /// over all views, frame reconstruction's filter (§5), and the image
    /// and visibility feedback read back (§3).
    pub fn render(&mut self, gpu: &Gpu, inputs: &RenderInputs) -> Result<Rendered> {
        let RenderInputs {
            index,
            scene,
            views,
            settings,
            ..
        } = *inputs;
        let start = std::time::Instant::now();
        if index.is_empty() {
            bail!("render: empty spatial index");
        }
        let (gviews, pixels) = gpu_views(views, settings)?;
        if pixels == 0 {
            return Ok(Rendered::nothing(views.len(), index.len()));
        }
        let img_size = pixels * 16;
        if img_size > gpu.device.limits().max_storage_buffer_binding_size {
            bail!("render: {pixels} pixels in one frame exceed the GPU's storage binding limit");
        }
        let tiles_start = std::time::Instant::now();
        let cull = self.cull(inputs);
        let mut tiles = tiles::tiles(views, scene, index, cull, settings.subframe.is_some());
        let tool_tiles = tiles::flag_regions(
            &mut tiles,
            views,
            scene,
            &settings.tool_regions,
            settings.subframe.is_some(),
        );
        let tiles_seconds = tiles_start.elapsed().as_secs_f64();
        let (rows, prediction_reset) =
            self.upload(gpu, inputs, &gviews, &tiles, tool_tiles, img_size)?;
        let pipeline = self.kernel(gpu, inputs, false)?.clone();
        let tool_pipeline = match tool_tiles {
            0 => None,
            _ => Some(self.kernel(gpu, inputs, true)?.clone()),
        };
        let fb_size = index.len() as u64 * 4;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        if settings.record_depth && settings.predict[0] == 0.0 {
            // Tiles left out write no depth: theirs reads 0, no surface.
            enc.clear_buffer(&self.frame.prediction.buffer, 0, None);
        }
        let passes = [
            (tool_pipeline.as_ref(), tool_tiles),
            (Some(&pipeline), tiles.len() - tool_tiles),
        ];
        self.encode_rays(&mut enc, &passes, rows, img_size, fb_size, settings);
        if let (Some(k), Some(reset)) = (settings.subframe, settings.reconstruct) {
            self.encode_reconstruction(gpu, &mut enc, views, k, reset)?;
        }
        let fr = &self.frame;
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
        let mut rendered = self.read_back(gpu, &gviews, img_size, fb_size, settings)?;
        rendered.seconds = start.elapsed().as_secs_f64();
        rendered.prediction_reset = prediction_reset;
        rendered.tiles = tiles.len() as u64;
        rendered.tiles_seconds = tiles_seconds;
        Ok(rendered)
    }

    /// Which tiles the dispatch runs: a kernel that skips empty space adds
    /// nothing where a ray meets no leaf with data (or, with macrocells, no
    /// cell with data), whatever its tools; the others (enhancers that add
    /// opacity, refraction, the isosurface) need every ray through the
    /// volume's box. Multilevel sampling blends a leaf's
    /// parent and grandparent into its samples, so its own empty cells do
    /// not bound what a ray meets there: leaves, not cells.
    fn cull<'a>(&self, inputs: &RenderInputs<'a>) -> tiles::Cull<'a> {
        let s = inputs.settings;
        let plain = s.kernel.skips_empty_space();
        let macrocells = s.macrocells && plain && inputs.pool.cells.per_axis > 0;
        let multilevel = s.multilevel.is_some() && !s.kernel.iso;
        match (plain, macrocells && !multilevel) {
            _ if !s.tile_culling => tiles::Cull::Off,
            (false, _) => tiles::Cull::Volume,
            (true, false) => tiles::Cull::Leaves,
            (true, true) => tiles::Cull::Cells(&inputs.pool.cells),
        }
    }

    /// Writes the frame's constants, its table of views, index and tiles,
    /// and the tools' parameters; grows the frame's buffers and remakes the
    /// bind group where needed. Returns the table's rows and whether the
    /// prediction buffer had just been made.
    fn upload(
        &mut self,
        gpu: &Gpu,
        inputs: &RenderInputs,
        gviews: &[GpuView],
        tiles: &[[u32; 2]],
        tool_tiles: usize,
        img_size: u64,
    ) -> Result<(usize, bool)> {
        let RenderInputs {
            pool,
            index,
            tf,
            scene,
            settings,
            ..
        } = *inputs;
        let mut frame = constants::frame_constants(pool, tf, scene, settings);
        let table = frame::frame_table(gviews, index, pool, tiles);
        let most = texels::ROW as u64 * gpu.device.limits().max_texture_dimension_2d as u64;
        if table.texels.len() as u64 > most {
            bail!(
                "render: the frame's views, index and tiles need {} texels; the GPU's largest table holds {most}",
                table.texels.len()
            );
        }
        frame.dispatch = [
            tiles.len() as u32,
            table.index,
            table.tiles,
            tool_tiles as u32,
        ];
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
            .write_buffer(&fr.constants, 0, bytemuck::bytes_of(&frame));
        let mut texels = table.texels;
        let rows = texels.len().div_ceil(texels::ROW as usize);
        texels.resize(rows * texels::ROW as usize, [0; 4]);
        gpu.queue
            .write_buffer(&fr.table_staging.buffer, 0, bytemuck::cast_slice(&texels));
        if !matches!(&fr.bind, Some((_, t, p)) if *t == tf.id && *p == pool.id) {
            let bound = bindings::Bound {
                pool,
                tf,
                sampler: &self.sampler,
                tools: &self.tools,
                grid: tf.grid.as_ref().map_or(&self.no_grid, |g| &g.1),
                grid_sampler: &self.grid_sampler,
                layers: &self.layers,
            };
            let bind = bindings::group(gpu, &self.bind_layout, fr, &bound);
            self.frame.bind = Some((bind, tf.id, pool.id));
            self.frame.made.bind_groups += 1;
        }
        gpu.queue
            .write_buffer(&self.tools, 0, bytemuck::cast_slice(&settings.tools));
        let n = settings.kernel.layers as usize;
        if n > 0 {
            if tf.layers.len() != n || pool.channels < 1 + n as u32 {
                bail!(
                    "render: {n} layers, but the table holds {} and the pool {} channels",
                    tf.layers.len(),
                    pool.channels
                );
            }
            let mut layers = settings.layers;
            for (l, t) in layers.iter_mut().zip(&tf.layers) {
                l.table = [t.table[0], t.table[1], t.table[2], l.table[3]];
                l.at = t.at;
                l.aux = t.aux;
            }
            gpu.queue
                .write_buffer(&self.layers, 0, bytemuck::cast_slice(&layers));
        }
        Ok((rows, prediction_reset))
    }

    /// The kernel this frame runs: the closed form's pieces where the
    /// kernel uses it, else the 2D table where asked for and filterable,
    /// else the exact table.
    /// `tool_tiles`: the variant for the tiles that meet a tool's region
    /// (`TOOL_TILES`).
    fn kernel(
        &mut self,
        gpu: &Gpu,
        inputs: &RenderInputs,
        tool_tiles: bool,
    ) -> Result<&wgpu::ComputePipeline> {
        let RenderInputs {
            pool, tf, settings, ..
        } = *inputs;
        let k = &settings.kernel;
        // Registered layers: the look-ahead fetches the volume's value alone.
        let layered = k.layers > 0;
        let macrocells = settings.macrocells && k.skips_empty_space() && pool.cells.per_axis > 0;
        let closed_pieces = tf
            .closed_pieces
            .filter(|_| settings.preintegration == Preintegration::Analytic && !k.iso);
        let closed = closed_pieces.is_some();
        let grid = tf.wants_grid(settings.preintegration)
            && self.grid_filterable
            && !k.iso
            && tf.grid.is_some();
        let lookahead = settings.lookahead && self.float_pool && (grid || closed) && !layered;
        let refine = settings.refine_parts() > 1
            && !k.iso
            && !layered
            && can_be_opaque(
                inputs.index,
                inputs.scene,
                inputs.views,
                tf.max_extinction,
                settings,
            );
        self.pipeline(
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
                lookahead,
                tool_tiles,
                refine,
            ],
            closed_pieces.unwrap_or(0),
        )
    }

    /// The table's copy, one zeroing of the visibility feedback for all
    /// views (G10 §5), the image's zeroing (pixels of the tiles left out
    /// stay zero) and the dispatches over the listed tiles: the tiles that
    /// meet a tool's region with the kernel that computes what its
    /// enhancers read, then the others (`passes`: each pipeline and its
    /// count of tiles, in the list's order).
    fn encode_rays(
        &self,
        enc: &mut wgpu::CommandEncoder,
        passes: &[(Option<&wgpu::ComputePipeline>, usize); 2],
        rows: usize,
        img_size: u64,
        fb_size: u64,
        settings: &RenderSettings,
    ) {
        let fr = &self.frame;
        let bind = &fr.bind.as_ref().expect("made by upload").0;
        fr.table
            .copy_rows(enc, &fr.table_staging.buffer, rows as u32);
        enc.clear_buffer(&fr.feedback.buffer, 0, Some(fb_size));
        if settings.count_samples {
            enc.clear_buffer(&fr.counters, 0, None);
        }
        enc.clear_buffer(&fr.image.buffer, 0, Some(img_size));
        for &(pipeline, n) in passes {
            let Some(pipeline) = pipeline.filter(|_| n > 0) else {
                continue;
            };
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            let n = n as u32;
            pass.dispatch_workgroups(
                n.min(tiles::TILES_PER_ROW),
                n.div_ceil(tiles::TILES_PER_ROW),
                1,
            );
        }
    }

    /// Frame reconstruction's filter over the image buffer, on the device,
    /// for sub-frame `k` (G10 §5).
    fn encode_reconstruction(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        views: &[View],
        k: u32,
        reset: bool,
    ) -> Result<()> {
        let filter = match &mut self.subframes {
            Some(f) => f,
            None => self.subframes.insert(subframes::SubframeFilter::new(gpu)?),
        };
        let sizes: Vec<[u32; 2]> = views.iter().map(|v| v.resolution).collect();
        let fr = &self.frame;
        // The image buffer's generation: the count of buffers made changes
        // whenever it is replaced.
        filter.encode(
            gpu,
            enc,
            &fr.image.buffer,
            fr.made.buffers,
            &sizes,
            k,
            reset,
        );
        Ok(())
    }

    /// Waits for the frame and reads back each view's pixels, the
    /// visibility feedback and the sample count.
    fn read_back(
        &self,
        gpu: &Gpu,
        gviews: &[GpuView],
        img_size: u64,
        fb_size: u64,
        settings: &RenderSettings,
    ) -> Result<Rendered> {
        let readback = &self.frame.readback.buffer;
        let data = gpu.map_read(readback.slice(..img_size + fb_size + COUNTERS), "the frame")?;
        let px: &[[f32; 4]] = bytemuck::cast_slice(&data[..img_size as usize]);
        let images = gviews
            .iter()
            .map(|v| {
                let (off, n) = (v.size[2] as usize, (v.size[0] * v.size[1]) as usize);
                px[off..off + n].to_vec()
            })
            .collect();
        let feedback =
            bytemuck::cast_slice(&data[img_size as usize..(img_size + fb_size) as usize]).to_vec();
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
            samples,
            ..Rendered::nothing(0, 0)
        })
    }
}

/// Each view as the kernel reads it (its screen region, eye, observer and
/// first pixel: G10 Eq. 1's ray), and the frame's pixel count.
fn gpu_views(views: &[View], settings: &RenderSettings) -> Result<(Vec<GpuView>, u64)> {
    let mut gviews = Vec::with_capacity(views.len());
    let mut pixels = 0u64;
    let f = |v: [f64; 3], w: f64| [v[0] as f32, v[1] as f32, v[2] as f32, w as f32];
    for v in views {
        let [w, h] = v.resolution;
        if w > MAX_VIEW_SIDE || h > MAX_VIEW_SIDE {
            bail!("render: a {w}×{h} view exceeds {MAX_VIEW_SIDE} pixels per side");
        }
        gviews.push(GpuView {
            region: v.region.map(|x| x as f32),
            eye: f(v.eye, v.eta),
            observer: f(v.observer, 0.0),
            size: [w, h, pixels as u32, settings.subframe.map_or(0, |k| k + 1)],
        });
        pixels += w as u64 * h as u64;
        if pixels > MAX_FRAME_PIXELS {
            bail!(
                "render: the views of one frame have more than {MAX_FRAME_PIXELS} pixels together"
            );
        }
    }
    Ok((gviews, pixels))
}

impl Rendered {
    /// A frame with no pixels: empty images and no leaf traversed.
    fn nothing(views: usize, nodes: usize) -> Rendered {
        Rendered {
            images: vec![Vec::new(); views],
            feedback: vec![0; nodes],
            seconds: 0.0,
            prediction_reset: false,
            samples: 0,
            tiles: 0,
            tiles_seconds: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::longest_voxel_along;
    use glam::DVec3;
    use parallax_common::camera::{Placement, View};

    /// The largest 1 / |d ⊘ e| over a view's rays, pixel by pixel (the
    /// kernel's `voxel_along` on the directions `View::ray` gives).
    fn sampled(view: &View, placement: &Placement, e: [f64; 3]) -> f64 {
        let rt = placement.rotation().transpose();
        let e = DVec3::from(e);
        let mut most: f64 = 0.0;
        for j in 0..view.resolution[1] {
            for i in 0..view.resolution[0] {
                let d = (rt * view.ray(i, j).1).normalize();
                most = most.max(1.0 / (d / e).length());
            }
        }
        most
    }

    /// The bound holds over every ray of windows and light field views at
    /// several turns of a thick-slice volume, and is tight enough to tell
    /// rays across the slices (about the in-plane voxel) from rays along
    /// them (the slice).
    #[test]
    fn the_voxel_along_the_rays_is_bounded() {
        let e = [1.0, 1.0, 10.7];
        let views = [
            View::window([40, 30], [0.4, 0.3], [0.0, 0.0, 1.2]),
            View::window([40, 30], [0.4, 0.3], [0.15, -0.1, 0.6]),
            View {
                eta: 1.0,
                eye: [0.3, 0.0, -1.5],
                ..View::window([40, 30], [0.4, 0.3], [0.0, 0.05, 1.0])
            },
        ];
        let mut across = 0.0f64;
        for rot in [
            [0.0, 0.0, 0.0],
            [90.0, 0.0, 0.0],
            [-70.0, 30.0, 0.0],
            [80.0, 10.0, 45.0],
            [0.0, 90.0, 0.0],
        ] {
            let placement = Placement {
                center: [0.0; 3],
                rotation_deg: rot,
                size: 0.25,
            };
            for v in &views {
                let bound = longest_voxel_along(std::slice::from_ref(v), &placement, e);
                let seen = sampled(v, &placement, e);
                assert!(
                    seen <= bound * (1.0 + 1e-9) && bound <= 10.7,
                    "{rot:?} {v:?}: rays see {seen}, bound {bound}"
                );
                if rot == [90.0, 0.0, 0.0] && v.eta == 0.0 {
                    across = across.max(bound);
                }
            }
        }
        // Turned 90° about x the slices' normal lies in the screen plane:
        // the rays cross the slices.
        assert!(across < 1.5, "across the slices: {across}");
        let along = longest_voxel_along(
            &views[..1],
            &Placement {
                center: [0.0; 3],
                rotation_deg: [0.0; 3],
                size: 0.25,
            },
            e,
        );
        assert_eq!(along, 10.7, "along the slices");
        // Cubic voxels are their edge.
        let placement = Placement {
            center: [0.0; 3],
            rotation_deg: [10.0, 20.0, 30.0],
            size: 0.25,
        };
        assert_eq!(longest_voxel_along(&views, &placement, [2.0; 3]), 2.0);
    }
}
