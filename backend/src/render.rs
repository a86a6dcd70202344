//! One back end's renderer: every frame, refine the cut for all of this
//! process's views (one loader, one brick pool, one spatial index, one
//! visibility feedback buffer: G10 §5), upload, build the index, ray cast.

use crate::gpu::Gpu;
use crate::index::SpatialIndex;
use crate::loader::{Affine, LayerSource, Loader, LoaderConfig};
use crate::raycast::{
    BrickPool, Filtering, KernelKey, Multilevel, Raycaster, RenderInputs, RenderSettings,
    SceneGeometry, TfTable, ToolParams,
};
use crate::reconstruct::{subframe_of, ViewHistory, SUBFRAMES};
use crate::store::{BrickEncoding, NodeKey, OctreeDb};
use anyhow::{bail, Context, Result};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{
    Filter, Interpolation, Layer, LayerTransform, Mode, Preintegration, RenderConfig, Shading,
};
use parallax_common::protocol::FrameStats;
use parallax_common::tf::labels;
use parallax_common::tf::{EmptinessTable, PreintTable, TransferFunction};
use parallax_common::tools::{PackContext, Tool, MAX_ENHANCERS};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// The transfer function as the renderer uses it.
struct ActiveTf {
    version: u64,
    table: TfTable,
    /// The CPU table `table` was made from (the 2D table is built from it
    /// when first asked for).
    preint: PreintTable,
    empty: EmptinessTable,
    /// Emptiness for refracting kernels: a range is skipped only where
    /// τ = 0 and ν = 1 (a transparent lens still bends rays).
    empty_refraction: EmptinessTable,
    /// The function itself (the isosurface takes its colour at the
    /// isovalue).
    function: TransferFunction,
}

/// A registered layer the renderer draws (`[[layer]]`: visible, with some
/// opacity, and a transfer function that is not empty over its data).
struct ActiveLayer {
    /// Its place among the scene's `[[layer]]`s.
    index: usize,
    spec: Layer,
    db: Arc<OctreeDb>,
    preint: PreintTable,
    empty: EmptinessTable,
    /// No-data voxels take this value (the layer's smallest).
    fill: f32,
    /// Its function's largest importance (MImDA's termination).
    max_importance: f64,
    /// Layer space → the volume's, for a layer on another grid.
    transform: Option<Affine>,
}

/// Layer `i`'s `transform = "scanner"`: the map from its volume space to
/// the scene volume's through the scanner's patient space, W_v⁻¹ ∘ W_l,
/// from the geometry both importers recorded (`Summary::world`).
fn scanner_map(db: &OctreeDb, ldb: &OctreeDb, i: usize) -> Result<Affine> {
    let world = |d: &OctreeDb, what: &str| -> Result<Affine> {
        let w = d.summary.world.with_context(|| {
            format!(
                "layer[{i}].transform = \"scanner\": {what} {} has no scanner geometry (its source file gave none, or it was imported before .pxo format 7); give the map's rows instead",
                d.path().display()
            )
        })?;
        Ok(Affine::from_rows(&w))
    };
    let (wv, wl) = (world(db, "the scene volume")?, world(ldb, "the layer")?);
    let inv = wv.inverse().with_context(|| {
        format!(
            "layer[{i}].transform = \"scanner\": the scene volume's scanner geometry is singular"
        )
    })?;
    Ok(inv.compose(&wl))
}

/// Layer `i`'s `transform`, checked: invertible, and placing some of the
/// layer's box inside the scene volume's.
fn placement(db: &OctreeDb, ldb: &OctreeDb, a: Affine, i: usize) -> Result<Affine> {
    if a.inverse().is_none() {
        bail!("layer[{i}].transform: the linear part is singular");
    }
    let ext = |d: &OctreeDb| crate::volume::extent(d.layout().dims, d.header.info.spacing);
    let (lo, hi) = a.map_box([0.0; 3], ext(ldb));
    let v = ext(db);
    if (0..3).any(|k| hi[k] <= 0.0 || lo[k] >= v[k]) {
        bail!(
            "layer[{i}].transform: places the layer's box at {lo:.1?} … {hi:.1?}, outside the scene volume's [0, 0, 0] … {v:.1?} (volume space, data units from the first voxel's corner)"
        );
    }
    Ok(a)
}

/// The brick caches (the CPU cache in the loader, the GPU pool) and the ray
/// caster over them, for a volume and the layers drawn with it, within the
/// budgets of `cfg`.
fn caches(
    gpu: &Gpu,
    db: &Arc<OctreeDb>,
    layers: &[ActiveLayer],
    cfg: &RenderConfig,
) -> Result<(Raycaster, BrickPool, Loader)> {
    let layout = *db.layout();
    let channels = BrickPool::channels_for(layers.len());
    // 8-bit codes where every medium's database holds them (filtered by
    // the texture unit), else f32.
    // A layer resampled onto the volume's bricks is kept in f32 (its
    // values are no longer the 8-bit codes of its database).
    let float = std::iter::once(&**db)
        .chain(layers.iter().map(|l| &*l.db))
        .any(|d| d.encoding() != BrickEncoding::U8Range)
        || layers.iter().any(|l| l.transform.is_some());
    let filtering = match cfg.interpolation {
        Interpolation::Hardware => Filtering::Hardware,
        Interpolation::Exact => Filtering::Exact,
    };
    let raycaster = Raycaster::new(gpu, float, filtering)?;
    let side = layout.stored_side() as u32;
    let budget = (cfg.gpu_cache_mb * (1 << 20) as f64) as u64;
    let slots = BrickPool::layered_slots_for_budget(budget, side, float, channels)
        .min(crate::index::MAX_INDEX_NODES as u32);
    // Refining a node needs all its children in core and on the GPU at
    // once (G08 §4): the smallest budgets that make progress hold the
    // root and one set of eight children (or just the root, for a
    // one-brick octree). Smaller ones are refused, with the figure.
    let (min_slots, min_bricks) = if layout.levels > 1 { (9, 8) } else { (1, 1) };
    if slots < min_slots {
        let slot_mib =
            BrickPool::layered_slot_bytes(side, float, channels) as f64 / (1 << 20) as f64;
        bail!(
                "render.gpu_cache_mb = {}: too small: the GPU pool must hold {min_slots} bricks (the root and one set of children) to refine; the smallest that works is {:.2}",
                cfg.gpu_cache_mb,
                (min_slots as f64 * slot_mib * 100.0).ceil() / 100.0
            );
    }
    let cpu_budget = (cfg.cpu_cache_mb * (1 << 20) as f64) as u64;
    let brick_bytes = layout.stored_len() as u64 * 4 * channels as u64;
    if cpu_budget < min_bricks * brick_bytes {
        let brick_mib = brick_bytes as f64 / (1 << 20) as f64;
        bail!(
                "render.cpu_cache_mb = {}: too small: the CPU cache must hold {min_bricks} bricks (one set of children) to refine; the smallest that works is {:.2}",
                cfg.cpu_cache_mb,
                (min_bricks as f64 * brick_mib * 100.0).ceil() / 100.0
            );
    }
    let pool = BrickPool::with_channels(gpu, slots, side, float, channels)?;
    let loader = Loader::with_layers(
        db.clone(),
        layer_sources(layers),
        LoaderConfig {
            cpu_budget_bytes: cpu_budget,
            gpu_slots: slots,
            upload_budget: cfg.upload_budget.max(1),
            accuracy: cfg.accuracy,
            opaque_detail: cfg.opaque_detail,
            use_feedback: cfg.visibility_feedback,
            frustum_culling: true,
            io_threads: 2,
        },
    );
    Ok((raycaster, pool, loader))
}

/// The loader's view of the layers drawn.
fn layer_sources(layers: &[ActiveLayer]) -> Vec<LayerSource> {
    layers
        .iter()
        .map(|l| LayerSource {
            db: l.db.clone(),
            empty: l.empty.clone(),
            transform: l.transform,
            nearest: l.spec.is_labels(),
        })
        .collect()
}

/// The smallest and largest variance of a database's stored bricks (B10
/// §4.5).
fn variance_range(db: &OctreeDb) -> (f32, f32) {
    db.nodes
        .iter()
        .filter(|n| n.is_stored() && n.variance.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), n| {
            (lo.min(n.variance), hi.max(n.variance))
        })
}

/// Time step `i` of a series, opened and checked to lie on the grid of
/// `first` (the same voxels, spacing, bricks and encoding: the steps share
/// the loader's geometry, the GPU pool and the ray caster).
fn open_step(path: &Path, i: usize, first: &OctreeDb) -> Result<Arc<OctreeDb>> {
    let db = OctreeDb::open(path).with_context(|| format!("series[{i}]"))?;
    let (a, b) = (&db.header, &first.header);
    if a.layout != b.layout || a.info.spacing != b.info.spacing || a.encoding != b.encoding {
        bail!(
            "{}: series[{i}]: {:?} voxels of {:?} in bricks of {} ({}), but the series' first step has {:?} of {:?} in bricks of {} ({}): every step must lie on one grid",
            path.display(),
            a.info.dims,
            a.info.spacing,
            a.layout.brick,
            a.encoding.name(),
            b.info.dims,
            b.info.spacing,
            b.layout.brick,
            b.encoding.name()
        );
    }
    Ok(Arc::new(db))
}

/// The scene's `[[layer]]`s the renderer draws, opened and checked against
/// the volume `db`: each on its grid (the same dimensions, bricks and
/// spacing), with its transfer function's tables over its data range.
/// Errors name the layer's field and file.
fn active_layers(
    db: &OctreeDb,
    specs: &[Layer],
    tfs: &[Option<TransferFunction>],
) -> Result<Vec<ActiveLayer>> {
    let mut out = Vec::new();
    for (i, spec) in specs.iter().enumerate() {
        if !spec.visible || spec.opacity <= 0.0 {
            continue;
        }
        let field = |f: &str, p: &Path| format!("layer[{i}].{f} = {}", p.display());
        let ldb = OctreeDb::open(&spec.volume).with_context(|| field("volume", &spec.volume))?;
        let (a, b) = (db.layout(), ldb.layout());
        let (sa, sb) = (db.header.info.spacing, ldb.header.info.spacing);
        let transform = match &spec.transform {
            Some(LayerTransform::Scanner) => {
                Some(placement(db, &ldb, scanner_map(db, &ldb, i)?, i)?)
            }
            Some(LayerTransform::Matrix(_)) => {
                let (m, t) = spec
                    .affine()
                    .with_context(|| format!("layer[{i}].transform: not an affine map"))?;
                Some(placement(db, &ldb, Affine { m, t }, i)?)
            }
            None => None,
        };
        let same_spacing =
            (0..3).all(|k| (sa[k] - sb[k]).abs() <= 1e-6 * sa[k].abs().max(sb[k].abs()));
        let same_grid =
            a.dims == b.dims && a.brick == b.brick && a.levels == b.levels && same_spacing;
        if transform.is_none() && !same_grid {
            bail!(
                "{}: the layer's grid ({:?} voxels of {:?}, bricks of {}) is not the scene volume's ({:?} voxels of {:?}, bricks of {}); a layer on another grid needs its place in the volume: layer[{i}].transform = [[a, b, c, t], …] (layer space → the volume's)",
                field("volume", &spec.volume),
                b.dims,
                sb,
                b.brick,
                a.dims,
                sa,
                a.brick
            );
        }
        let (f, file) = spec.function_file();
        let s = &ldb.summary;
        let tf = match tfs.get(i) {
            Some(Some(tf)) => tf.clone(),
            _ => {
                let tf = spec.load_function().with_context(|| field(f, file))?;
                // The scene's colour table lists every label the volume holds.
                if let (true, Some(present)) = (spec.is_labels(), &s.labels) {
                    labels::check_labels(&tf, present).with_context(|| {
                        format!("{}: {}", field(f, file), spec.volume.display())
                    })?;
                }
                tf
            }
        };
        // The table's range and bins, and the emptiness table.
        let (lo, hi, bins, empty) = match (&spec.labels, &s.labels) {
            // A node at each label, where the kernel reads its optics; the
            // labels' steps tell which bricks draw nothing.
            (Some(_), Some(labels)) => {
                let (a, b) = (labels[0], labels[labels.len() - 1]);
                let n = (b - a) as usize + 1;
                let steps = labels::label_steps(&tf, a, b);
                let (sa, sb) = (a as f64 - 0.5, b as f64 + 0.5);
                let empty = EmptinessTable::new(&steps, sa, sb, 4 * n)?;
                (a as f64, b as f64 + 1.0, n, empty)
            }
            (Some(_), None) => bail!(
                "{}: {} is not a label volume: import it with --labels (its coarser levels would average labels into other labels)",
                field(f, file),
                spec.volume.display()
            ),
            (None, _) => {
                let (lo, hi) = (s.value_min as f64, s.value_max as f64);
                let int = !ldb.header.info.voxel_type.is_float();
                let bins = PreintTable::suggested_bins(lo, hi, int);
                (lo, hi, bins, EmptinessTable::new(&tf, lo, hi, bins)?)
            }
        };
        if empty.is_empty(s.value_min as f64, s.value_max as f64) {
            continue; // nothing of it is visible: it costs nothing
        }
        if out.len() == parallax_common::config::MAX_LAYERS {
            bail!(
                "layer: more than {} layers are visible; the kernel combines at most that many with the volume",
                parallax_common::config::MAX_LAYERS
            );
        }
        out.push(ActiveLayer {
            index: i,
            transform,
            spec: spec.clone(),
            preint: PreintTable::new(&tf, lo, hi, bins).with_context(|| field(f, file))?,
            empty,
            fill: s.value_min,
            max_importance: tf.max_importance(),
            db: Arc::new(ldb),
        });
    }
    Ok(out)
}

pub struct Renderer {
    gpu: Gpu,
    /// The registered layers drawn with the volume (shaders/shared/layers.wgsl).
    layers: Vec<ActiveLayer>,
    /// The scene's layers as last set (drawn or not), and the settings the
    /// caches were made with (their budgets, when the drawn layers change).
    specs: Vec<Layer>,
    /// The layers' transfer functions where the live page replaced the
    /// scene's files (`[[layer]]` order).
    layer_tfs: Vec<Option<TransferFunction>>,
    budgets: RenderConfig,
    raycaster: Raycaster,
    pool: BrickPool,
    loader: Loader,
    /// The database drawn: the scene's volume, or its series' current step.
    db: Arc<OctreeDb>,
    /// A time series: each step's database (the scene's `series`), and the
    /// step drawn.
    series: Vec<PathBuf>,
    step: usize,
    /// The next step's loader, reading ahead what the drawn step's cut
    /// holds (`Loader::prefetch`); it becomes the loader at that step.
    next: Option<(usize, Loader)>,
    /// The data values the tables span: the volume's range, or the union
    /// of every step's, so that a transfer function maps a value the same
    /// way in every step.
    value_range: (f32, f32),
    tf: Option<ActiveTf>,
    /// Recent frames' index and visibility feedback, newest last: one frame
    /// (G10 §5), or one per sub-frame with frame reconstruction.
    last: VecDeque<(SpatialIndex, Vec<u32>)>,
    /// Frame reconstruction: each view's history, and what it was made
    /// under (a change of any of it invalidates the history). With the
    /// filter on the GPU the history lives there and `history` is empty.
    history: Vec<ViewHistory>,
    history_key: Option<HistoryKey>,
    /// Run frame reconstruction's filter on the GPU, after the rays and
    /// before the read-back (`raycast::subframes`); off, on the CPU after
    /// the read-back ([`ViewHistory`]). The same filter either way. On by
    /// default except on a CPU device, where the GPU's share of the cores
    /// is the CPU filter's, and the CPU filter is a little cheaper
    /// (docs/performance.md, "Frame reconstruction").
    pub reconstruct_on_gpu: bool,
    /// The stored bricks' smallest and largest variance (B10 §4.5).
    variance_range: (f32, f32),
    /// Prediction buffer: what it was filled under, and frames since the
    /// last full traversal.
    prediction: Option<(HistoryKey, u32)>,
    /// The tools (each an enhancer of the chain) and their version.
    tools: (u64, Vec<Tool>),
    /// The overlay's pipeline (tool geometry), made on first use.
    overlay: Option<crate::overlay::OverlayRenderer>,
    /// Wait for every posted read before refining (deterministic frames).
    pub sync_io: bool,
    /// The coarse copy of the volume the focus click is picked in, read on
    /// the first pick.
    pick_volume: Option<crate::pick::PickVolume>,
    /// The pool's empty macrocells were marked under another transfer
    /// function, or not kept up while macrocells were off.
    cells_stale: bool,
    /// The band pickers' value windows the pool's macrocells were marked
    /// under ([`Renderer::band_windows`]).
    cell_windows: Vec<(f64, f64)>,
    /// Count the samples each frame takes (`FrameStats::samples`).
    pub count_samples: bool,
    /// Run only the tiles whose rays can meet data (on unless a test
    /// compares against every tile).
    pub tile_culling: bool,
    /// Fetch samples one pass ahead on float pools with the 2D table (on
    /// unless a test compares against the plain loop).
    pub lookahead: bool,
    /// A series: read the next step's bricks ahead while drawing this one
    /// (on unless `parallax bench series` compares against it).
    pub prefetch: bool,
}

/// A rendered frame: one premultiplied RGBA image per view, and its figures.
pub struct Frame {
    pub images: Vec<Vec<[f32; 4]>>,
    pub stats: FrameStats,
    /// Isosurfaces: the prediction buffer steered this frame (not a full
    /// traversal).
    pub predicted: bool,
}

impl Renderer {
    pub fn new(database: &Path, cfg: &RenderConfig) -> Result<Self> {
        Self::with_adapter(
            database,
            cfg,
            &crate::gpu::AdapterRequest::from_env(None, 0),
        )
    }

    /// A renderer on the adapter `req` chooses (backend/src/gpu.rs).
    pub fn with_adapter(
        database: &Path,
        cfg: &RenderConfig,
        req: &crate::gpu::AdapterRequest,
    ) -> Result<Self> {
        Self::with_layers(database, &[], cfg, req)
    }

    /// A renderer of a volume and its registered layers (a scene's
    /// `[[layer]]`s; G10 §4), on the adapter `req` chooses. Layers that are
    /// hidden, have no opacity or whose transfer function is empty over
    /// their data are left out: nothing of them is read. The others must
    /// lie on the volume's grid; their bricks share one CPU cache and one
    /// GPU pool with it (each texel holding every layer's value), and one
    /// traversal serves all.
    pub fn with_layers(
        database: &Path,
        layers: &[Layer],
        cfg: &RenderConfig,
        req: &crate::gpu::AdapterRequest,
    ) -> Result<Self> {
        let db = Arc::new(OctreeDb::open(database)?);
        let specs = layers.to_vec();
        let layers = active_layers(&db, layers, &[])?;
        if !layers.is_empty() {
            cfg.check_layered("render")?;
        }
        let gpu = Gpu::with_request(req)?;
        let (raycaster, pool, loader) = caches(&gpu, &db, &layers, cfg)?;
        let variance_range = variance_range(&db);
        let value_range = (db.summary.value_min, db.summary.value_max);
        let reconstruct_on_gpu = gpu.info.device_type != wgpu::DeviceType::Cpu;
        Ok(Renderer {
            layers,
            specs,
            layer_tfs: Vec::new(),
            budgets: cfg.clone(),
            gpu,
            raycaster,
            pool,
            loader,
            db,
            series: Vec::new(),
            step: 0,
            next: None,
            value_range,
            tf: None,
            last: VecDeque::new(),
            history: Vec::new(),
            history_key: None,
            reconstruct_on_gpu,
            variance_range,
            prediction: None,
            tools: (0, Vec::new()),
            overlay: None,
            sync_io: false,
            pick_volume: None,
            cells_stale: false,
            cell_windows: Vec::new(),
            count_samples: false,
            tile_culling: true,
            lookahead: true,
            prefetch: true,
        })
    }

    /// The light field display this renderer's η > 0 views are shown on
    /// (their level of detail follows s(z), G10 §4).
    pub fn set_lightfield(&mut self, lightfield: Option<crate::loader::LightField>) {
        self.loader.set_lightfield(lightfield);
        if let Some((_, next)) = self.next.as_mut() {
            next.set_lightfield(lightfield);
        }
    }

    /// The ray caster's image buffer, holding the last frame's views
    /// (`Raycaster::image_buffer`).
    pub fn image_buffer(&self) -> &wgpu::Buffer {
        self.raycaster.image_buffer()
    }

    /// The device this renderer draws with (its windows present with it).
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    pub fn adapter(&self) -> &wgpu::AdapterInfo {
        &self.gpu.info
    }

    pub fn db(&self) -> &OctreeDb {
        &self.db
    }

    /// Makes the renderer draw a time series (a scene's `series`; its first
    /// step is the database the renderer was opened on): every step is
    /// opened and checked to lie on the first one's grid, and the tables
    /// span the union of their value ranges. Call before the transfer
    /// function is installed.
    pub fn set_series(&mut self, series: &[PathBuf]) -> Result<()> {
        if series.len() <= 1 {
            return Ok(());
        }
        let (mut lo, mut hi) = self.value_range;
        let (mut v_lo, mut v_hi) = self.variance_range;
        for (i, p) in series.iter().enumerate().skip(1) {
            let db = open_step(p, i, &self.db)?;
            lo = lo.min(db.summary.value_min);
            hi = hi.max(db.summary.value_max);
            let (a, b) = variance_range(&db);
            (v_lo, v_hi) = (v_lo.min(a), v_hi.max(b));
        }
        self.series = series.to_vec();
        self.step = 0;
        self.value_range = (lo, hi);
        self.variance_range = (v_lo, v_hi);
        self.series_loaders(None)?;
        if let Some(tf) = self.tf.take() {
            self.set_transfer_function(tf.version, &tf.function)?;
        }
        Ok(())
    }

    /// A series' loaders: the drawn step's (`current`, or the one the
    /// renderer has, on `self.db`) and the next step's, reading ahead,
    /// each with half of `render.cpu_cache_mb`: playing, the CPU cache
    /// holds the drawn step's bricks and the next one's.
    fn series_loaders(&mut self, current: Option<Loader>) -> Result<()> {
        let mut cfg = self.loader.config().clone();
        let total = (self.budgets.cpu_cache_mb * (1 << 20) as f64) as u64;
        cfg.cpu_budget_bytes = total / 2;
        let layout = self.db.layout();
        let brick_bytes =
            layout.stored_len() as u64 * 4 * BrickPool::channels_for(self.layers.len()) as u64;
        let min_bricks = if layout.levels > 1 { 8 } else { 1 };
        if cfg.cpu_budget_bytes < min_bricks * brick_bytes {
            bail!(
                "render.cpu_cache_mb = {}: too small for a series: half of it holds the drawn step's bricks and half the next step's, and each half must hold {min_bricks} bricks; the smallest that works is {:.2}",
                self.budgets.cpu_cache_mb,
                (2.0 * (min_bricks * brick_bytes) as f64 / (1 << 20) as f64 * 100.0).ceil() / 100.0
            );
        }
        match current {
            Some(l) => self.loader = l,
            None => self.loader.set_cpu_budget(cfg.cpu_budget_bytes),
        }
        self.loader.load_root();
        let n = (self.step + 1) % self.series.len();
        let db = open_step(&self.series[n], n, &self.db)?;
        self.next = Some((n, self.step_loader(db, &cfg)));
        Ok(())
    }

    /// A loader on one step's database, configured as the drawn one.
    fn step_loader(&self, db: Arc<OctreeDb>, cfg: &LoaderConfig) -> Loader {
        let mut loader = Loader::with_layers(db, layer_sources(&self.layers), cfg.clone());
        loader.set_lightfield(self.loader.lightfield());
        loader
    }

    /// The time steps this renderer draws (1 without a series).
    pub fn steps(&self) -> usize {
        self.series.len().max(1)
    }

    /// Draws time step `step` of the series from the next frame on: its
    /// database replaces the last step's in the loader, whose caches start
    /// empty (the GPU pool, the ray caster and the tables stay). Until its
    /// bricks arrive the cut holds the coarser levels it has, from the root
    /// (read at once), never a hole.
    pub fn set_step(&mut self, step: usize) -> Result<()> {
        if step == self.step {
            return Ok(());
        }
        if step >= self.steps() {
            bail!("time step {step}: the scene has {} step(s)", self.steps());
        }
        // The loader that read ahead for this step, or a new one.
        let loader = match self.next.take() {
            Some((n, l)) if n == step => l,
            _ => {
                let db = open_step(&self.series[step], step, &self.db)?;
                self.step_loader(db, self.loader.config())
            }
        };
        self.db = loader.db().clone();
        self.step = step;
        self.series_loaders(Some(loader))?;
        self.last.clear();
        self.history.clear();
        self.history_key = None;
        self.prediction = None;
        self.pick_volume = None;
        self.cells_stale = true;
        Ok(())
    }

    /// Installs a transfer function: pre-integration table over the
    /// dataset's value range (G10 §4) and its emptiness table (G08 §4).
    pub fn set_transfer_function(&mut self, version: u64, tf: &TransferFunction) -> Result<()> {
        let (lo, hi) = (self.value_range.0 as f64, self.value_range.1 as f64);
        let integer = !self.db.header.info.voxel_type.is_float();
        let bins = PreintTable::suggested_bins(lo, hi, integer);
        let table = PreintTable::new(tf, lo, hi, bins)?;
        let empty = EmptinessTable::new(tf, lo, hi, bins)?;
        let empty_refraction = EmptinessTable::new(&tf.refraction_as_extinction(), lo, hi, bins)?;
        let layer_tables: Vec<(&PreintTable, f64)> = self
            .layers
            .iter()
            .map(|l| (&l.preint, l.max_importance))
            .collect();
        self.tf = Some(ActiveTf {
            version,
            table: TfTable::with_layers(&self.gpu, &table, tf, &layer_tables),
            preint: table,
            empty,
            empty_refraction,
            function: tf.clone(),
        });
        if let Some(tf) = &self.tf {
            tracing::info!(
                closed_form_pieces = ?tf.table.closed_pieces(),
                auto = ?self.preintegration(Preintegration::Auto),
                "transfer function installed"
            );
        }
        // Last frame's visibility was for another transfer function.
        self.last.clear();
        self.cells_stale = true;
        Ok(())
    }

    /// The display-space point the live coordinator's focus click hits (see
    /// [`crate::pick::PickVolume::pick`]): the first point along the ray
    /// origin + t·dir (display space, t ≥ 0) where the accumulated opacity
    /// under the renderer's current transfer function reaches ½, or `None`
    /// when the ray misses the volume or never gets that opaque. The coarse
    /// pick volume (at most [`crate::pick::PICK_VOXELS`] voxels) is read on
    /// first use and kept. Tools, clip planes and the isosurface mode are not
    /// taken into account.
    pub fn pick(
        &mut self,
        placement: &Placement,
        origin: [f64; 3],
        dir: [f64; 3],
    ) -> Result<Option<[f64; 3]>> {
        if self.tf.is_none() {
            bail!("pick: no transfer function set");
        }
        if self.pick_volume.is_none() {
            let volume = crate::pick::PickVolume::from_db(&self.db, crate::pick::PICK_VOXELS)
                .context("pick: reading the coarse volume")?;
            self.pick_volume = Some(volume);
        }
        let tf = &self.tf.as_ref().expect("checked above").function;
        let volume = self.pick_volume.as_ref().expect("read above");
        Ok(volume.pick(tf, placement, origin, dir, crate::pick::PICK_THRESHOLD))
    }

    /// A band picker's band grown from the point a display-space ray picks
    /// (where its opacity reaches ½): region growing in the coarse copy
    /// the picks use, within `tolerance` × the transfer function's value
    /// span of the point's value ([`crate::pick::PickVolume::grow_band`]).
    /// None where the ray picks nothing.
    pub fn grow_band(
        &mut self,
        placement: &Placement,
        origin: [f64; 3],
        dir: [f64; 3],
        tolerance: f64,
    ) -> Result<Option<[f64; 4]>> {
        let Some(hit) = self.pick(placement, origin, dir)? else {
            return Ok(None);
        };
        let volume = self.pick_volume.as_ref().expect("read by the pick");
        let extent = volume.extent();
        let (seed, _) =
            placement.ray_to_volume(extent, glam::DVec3::from(hit), glam::DVec3::from(dir));
        let p = self
            .tf
            .as_ref()
            .expect("checked by the pick")
            .function
            .points();
        let span = match (p.first(), p.last()) {
            (Some(a), Some(b)) if b.value > a.value => b.value - a.value,
            _ => 1.0,
        };
        Ok(volume.grow_band(seed, tolerance * span))
    }

    /// Turns the loader's view-frustum culling on or off (tests compare the
    /// images with and without it).
    pub fn set_frustum_culling(&mut self, on: bool) {
        self.loader.set_frustum_culling(on);
    }

    /// The bricks resident in the GPU pool (the cut's bricks with data, and
    /// whatever the pool still caches).
    pub fn resident_bricks(&self) -> Vec<NodeKey> {
        self.db
            .nodes
            .iter()
            .map(|n| n.key)
            .filter(|&k| self.loader.gpu_slot(k).is_some())
            .collect()
    }

    pub fn tf_version(&self) -> Option<u64> {
        self.tf.as_ref().map(|t| t.version)
    }

    /// Installs the tools: from the next frame each drives one enhancer of
    /// the chain, in order (G10 §4–5).
    pub fn set_tools(&mut self, version: u64, tools: &[Tool]) -> Result<()> {
        if tools.len() > MAX_ENHANCERS {
            bail!(
                "{} tools: at most {MAX_ENHANCERS} enhancers can be chained",
                tools.len()
            );
        }
        self.tools = (version, tools.to_vec());
        Ok(())
    }

    pub fn tools_version(&self) -> u64 {
        self.tools.0
    }

    /// Pipelines the ray caster has built (one per combination used).
    pub fn pipeline_count(&self) -> usize {
        self.raycaster.pipeline_count()
    }

    /// Per-frame GPU buffers and bind groups the ray caster has made.
    pub fn frame_buffer_counts(&self) -> crate::raycast::FrameBufferCounts {
        self.raycaster.frame_buffer_counts()
    }

    /// The tools with what they take from the transfer function resolved
    /// (a band picker's `points`).
    fn resolved_tools(&self) -> Vec<Tool> {
        let values: Vec<f64> = self.tf.as_ref().map_or_else(Vec::new, |t| {
            t.function.points().iter().map(|p| p.value).collect()
        });
        self.tools.1.iter().map(|t| t.resolved(&values)).collect()
    }

    /// The value windows [b₀, b₃] of the tools that declare one (the band
    /// picker) and act fully on every ray of this frame (G10 §4): where
    /// ω_a = 1 a segment whose
    /// values all miss a picker's band gets opacity × 0 (and importance 0),
    /// exactly nothing, so a node or a macrocell whose value range misses a
    /// window is empty for this frame — the loader does not load it, the
    /// tiles and the macrocells skip it. ω_a is 1 where −a·v ≥ a_h; it is
    /// tested on each view's corner and edge rays (every 1/32 of a side)
    /// with a margin of 10⁻⁴. DVR and MImDA without refraction only.
    fn band_windows(
        ctx: &PackContext,
        tools: &[Tool],
        views: &[View],
        cfg: &RenderConfig,
    ) -> Vec<(f64, f64)> {
        if cfg.mode == Mode::Iso || cfg.refraction {
            return Vec::new();
        }
        let mut out = Vec::new();
        for t in tools {
            let Some(window) = t.value_window() else {
                continue;
            };
            if !t.acts_on(ctx) {
                continue;
            }
            let axis = window.axis;
            let aligned = views.iter().all(|v| {
                let [w, h] = v.resolution;
                let (sw, sh) = (w.div_ceil(32).max(1), h.div_ceil(32).max(1));
                let edge = (0..w)
                    .step_by(sw as usize)
                    .chain([w - 1])
                    .flat_map(|i| [(i, 0), (i, h - 1)])
                    .chain(
                        (0..h)
                            .step_by(sh as usize)
                            .chain([h - 1])
                            .flat_map(|j| [(0, j), (w - 1, j)]),
                    );
                edge.into_iter().all(|(i, j)| {
                    let (_, d) = v.ray(i, j);
                    -axis.dot(d) >= window.cos_full + 1e-4
                })
            });
            if aligned {
                out.push((window.range[0], window.range[1]));
            }
        }
        out
    }

    /// Where the volume is and how steep its data can be, for the tools.
    fn pack_context(&self, placement: &Placement) -> PackContext {
        PackContext {
            placement: *placement,
            extent: self.geometry(placement).extent(),
            gradient_max: self.gradient_max(),
        }
    }

    /// The kernel and its parameters for this frame's scene state.
    fn settings(&self, ctx: &PackContext, resolved: &[Tool], cfg: &RenderConfig) -> RenderSettings {
        // Tools that cannot change the volume's box are left out of the
        // kernel: a scene pays nothing for a tool moved away.
        let acting: Vec<&Tool> = resolved.iter().filter(|t| t.acts_on(ctx)).collect();
        let mut tools = [ToolParams::default(); MAX_ENHANCERS];
        for (p, t) in tools.iter_mut().zip(&acting) {
            let [a, b, c, d] = t.pack(ctx);
            *p = ToolParams { a, b, c, d };
        }
        let tool_regions = acting.iter().filter_map(|t| t.region(ctx)).collect();
        RenderSettings {
            reconstruct: None,
            step_factor: cfg.step_factor as f32,
            early_termination: cfg.early_termination as f32,
            shading: cfg.shading == Shading::Phong,
            kernel: KernelKey {
                // MImDA at γ = 0 is DVR: β = 1 on every segment, the same
                // operations (steppers/mimda.wgsl). The DVR kernel gives
                // that image without reading the importance.
                mimda: cfg.mode == Mode::Mimda && cfg.gamma > 0.0,
                refraction: cfg.refraction,
                iso: cfg.mode == Mode::Iso,
                enhancers: acting.iter().map(|t| t.enhancer()).collect(),
                layers: self.layers.len() as u32,
                layer_end: self.tf.as_ref().is_some_and(|t| t.table.layers_end_path()),
                labels: self
                    .layers
                    .iter()
                    .enumerate()
                    .filter(|(_, l)| l.spec.is_labels())
                    .fold(0, |m, (k, _)| m | 1 << k),
            },
            gamma: if cfg.mode == Mode::Mimda {
                cfg.gamma as f32
            } else {
                0.0
            },
            iso: match (cfg.mode, cfg.isovalue, &self.tf) {
                (Mode::Iso, Some(v), Some(tf)) => {
                    let c = tf.function.eval(v).color;
                    [v as f32, c[0] as f32, c[1] as f32, c[2] as f32]
                }
                _ => [0.0; 4],
            },
            subframe: None,
            predict: [0.0; 4],
            record_depth: cfg.overlay.show && cfg.overlay.depth,
            tools,
            tool_regions,
            macrocells: cfg.macrocells,
            count_samples: self.count_samples,
            tile_culling: self.tile_culling,
            lookahead: self.lookahead,
            adaptive_step: cfg.adaptive_step,
            refinement: cfg.refinement,
            sub_pixel: if cfg.accuracy < 1.0 {
                cfg.accuracy as f32
            } else {
                0.0
            },
            multilevel: cfg.multilevel.then(|| Multilevel {
                accuracy: cfg.accuracy as f32,
                lightfield: self.loader.lightfield().map(|lf| {
                    (
                        lf.pixel_size as f32,
                        (lf.angular_accuracy_deg.to_radians() / 2.0).tan() as f32,
                    )
                }),
            }),
            tricubic: cfg.filter == Filter::Tricubic,
            preintegration: self.preintegration(cfg.preintegration),
            layers: self.layer_params(&ctx.placement),
        }
    }

    /// The way to the exact integral this frame takes: "auto" resolved for
    /// this device and the transfer function (`Preintegration::resolve`).
    pub fn preintegration(&self, asked: Preintegration) -> Preintegration {
        let pieces = self.tf.as_ref().and_then(|tf| tf.table.closed_pieces());
        asked.resolve(pieces, self.gpu.info.device_type == wgpu::DeviceType::Cpu)
    }

    /// The registered layers' opacity and view-dependent opacity, its axis
    /// turned into volume space (the ray directions' space).
    fn layer_params(
        &self,
        placement: &Placement,
    ) -> [crate::raycast::params::LayerParams; parallax_common::config::MAX_LAYERS] {
        let mut out =
            [crate::raycast::params::LayerParams::default(); parallax_common::config::MAX_LAYERS];
        let rt = placement.rotation().transpose();
        for (p, l) in out.iter_mut().zip(&self.layers) {
            p.table[3] = l.spec.opacity as f32;
            if let Some(v) = &l.spec.view_opacity {
                let a = (rt * glam::DVec3::from(v.axis)).normalize();
                let [from, to] = v.angles_deg.map(f64::to_radians);
                let inv = if to != from {
                    (1.0 / (to - from)) as f32
                } else {
                    f32::MAX
                };
                p.axis = [a.x as f32, a.y as f32, a.z as f32, 1.0];
                p.angles = [from as f32, inv, 0.0, 0.0];
            }
        }
        out
    }

    /// Sets the scene's registered layers' visibility and opacity (the
    /// live page, scripts; in `[[layer]]` order, empty: as the scene file
    /// says). An opacity change is the next frame's constant; a change of
    /// which layers are drawn (shown or hidden, an opacity to or from 0)
    /// remakes the caches, the pool and the tables for the new set (a
    /// hidden layer costs nothing).
    pub fn set_layer_controls(
        &mut self,
        controls: &[parallax_common::protocol::LayerControl],
    ) -> Result<()> {
        let specs: Vec<Layer> = match controls {
            [] => self.specs.clone(),
            c => {
                if c.len() != self.specs.len() {
                    bail!(
                        "layers: {} controls for the scene's {} layers",
                        c.len(),
                        self.specs.len()
                    );
                }
                self.specs
                    .iter()
                    .zip(c)
                    .map(|(s, c)| Layer {
                        visible: c.visible,
                        opacity: c.opacity.clamp(0.0, 1.0),
                        ..s.clone()
                    })
                    .collect()
            }
        };
        let drawn = |l: &Layer| l.visible && l.opacity > 0.0;
        let same_set = self
            .specs
            .iter()
            .zip(&specs)
            .all(|(a, b)| drawn(a) == drawn(b));
        if same_set {
            for l in &mut self.layers {
                l.spec.opacity = specs[l.index].opacity;
            }
            self.specs = specs;
            return Ok(());
        }
        self.specs = specs;
        self.rebuild_layers()
    }

    /// Replaces the layers' transfer functions (`[[layer]]` order; `None`:
    /// the scene's file), as the live page edits them. A change remakes the
    /// caches (a layer's bricks are read where its function sees data).
    pub fn set_layer_functions(&mut self, tfs: &[Option<TransferFunction>]) -> Result<()> {
        if tfs.len() != self.specs.len() {
            bail!(
                "layers: {} transfer functions for the scene's {} layers",
                tfs.len(),
                self.specs.len()
            );
        }
        if tfs == self.layer_tfs.as_slice() {
            return Ok(());
        }
        self.layer_tfs = tfs.to_vec();
        self.rebuild_layers()
    }

    /// Opens the layers drawn under the current controls and functions and
    /// remakes the caches, the pool and the tables for them.
    fn rebuild_layers(&mut self) -> Result<()> {
        let layers = active_layers(&self.db, &self.specs, &self.layer_tfs)?;
        let (raycaster, pool, mut loader) = caches(&self.gpu, &self.db, &layers, &self.budgets)?;
        loader.set_lightfield(self.loader.lightfield());
        loader.set_frustum_culling(self.loader.config().frustum_culling);
        self.layers = layers;
        self.raycaster = raycaster;
        self.pool = pool;
        self.loader = loader;
        if self.series.len() > 1 {
            self.series_loaders(None)?;
        }
        self.last.clear();
        self.history.clear();
        self.history_key = None;
        self.prediction = None;
        self.cells_stale = true;
        if let Some(tf) = self.tf.take() {
            self.set_transfer_function(tf.version, &tf.function)?;
        }
        Ok(())
    }

    /// How many of the scene's registered layers this renderer draws (the
    /// others are hidden, without opacity, or empty under their transfer
    /// function).
    pub fn layer_count(&self) -> usize {
        self.layers.len()
    }

    /// ∇_max of the probe's η (G10 Eq. 5): the transfer function's value
    /// span over the finest voxel, the steepest change one voxel can carry
    /// within the values the function maps.
    fn gradient_max(&self) -> f64 {
        let span = self.tf.as_ref().map_or(1.0, |t| {
            let p = t.function.points();
            match (p.first(), p.last()) {
                (Some(a), Some(b)) if b.value > a.value => b.value - a.value,
                _ => 1.0,
            }
        });
        span / self.finest_voxel().max(1e-30)
    }

    /// The smallest voxel side of the volume (data length units).
    fn finest_voxel(&self) -> f64 {
        let spacing = self.db.header.info.spacing;
        spacing.iter().cloned().fold(f64::INFINITY, f64::min)
    }

    fn geometry(&self, placement: &Placement) -> SceneGeometry {
        SceneGeometry::new(*placement, *self.db.layout(), self.db.header.info.spacing)
    }

    /// Renders one frame of `views`, in G10 §5's stages: refine the cut
    /// with the visibility feedback, upload what it needs, build the
    /// spatial index, ray cast every view in one dispatch, keep the
    /// feedback for the next frame, and reconstruct the frame.
    pub fn frame(
        &mut self,
        frame: u64,
        placement: &Placement,
        views: &[View],
        cfg: &RenderConfig,
    ) -> Result<Frame> {
        let start = Instant::now();
        if !self.layers.is_empty() {
            cfg.check_layered("render")?;
        }
        if let Some(tf) = self.tf.as_mut() {
            if tf.table.wants_grid(cfg.preintegration) {
                tf.table.build_grid(&self.gpu, &tf.preint);
            }
        }
        self.tf
            .as_ref()
            .context("render: no transfer function set")?;
        let mut stats = FrameStats {
            frame,
            views: views.len() as u32,
            ..Default::default()
        };
        if self.sync_io {
            self.loader.wait_idle();
        }
        self.loader.set_accuracy(cfg.accuracy);
        // Opaque voxels are held to accuracy / opaque_detail; isosurfaces'
        // nodes follow the isovalue, not the function's opacity, and
        // multilevel sampling blends every leaf by `accuracy` alone (it
        // would blend an opaque leaf back towards its parent).
        let opacity = match (&self.tf, cfg.mode) {
            (Some(tf), Mode::Dvr | Mode::Mimda) if !cfg.multilevel => Some(&tf.function),
            _ => None,
        };
        self.loader.set_opacity(cfg.opaque_detail, opacity);
        let t = Instant::now();
        // The tools as this frame sees them, once: resolved against the
        // transfer function and placed by `ctx`.
        let ctx = self.pack_context(placement);
        let tools = self.resolved_tools();
        let windows = Self::band_windows(&ctx, &tools, views, cfg);
        if windows != self.cell_windows {
            self.cell_windows.clone_from(&windows);
            self.cells_stale = true;
        }
        let cut = self.refine(frame, views, placement, cfg, &windows)?;
        // A brick that fails its read or checksum is not fatal: the loader
        // never asks for it again and its parent stays a leaf (G08 §4 never
        // blocks on data); the frame names it.
        stats.bad_bricks = self.loader.errors();
        for b in &stats.bad_bricks {
            tracing::warn!("{b}: its parent stays a leaf");
        }
        if let Some((_, next)) = self.next.as_mut().filter(|_| self.prefetch) {
            // A series: the next step reads ahead the bricks this one
            // draws, coarsest first (waiting for them with --sync, so that
            // a frame depends only on the frames before it).
            let mut keys: Vec<NodeKey> = cut
                .cut
                .iter()
                .filter(|(_, n)| n.slot.is_some())
                .map(|(&k, _)| k)
                .collect();
            keys.sort_unstable();
            stats.prefetched = next.prefetch(&keys) as u64;
            if self.sync_io {
                next.wait_idle();
            }
        }
        stats.refine_ms = ms(t);

        let t = Instant::now();
        self.upload(&cut, cfg, &windows)?;
        stats.upload_ms = ms(t);

        let t = Instant::now();
        let index = SpatialIndex::build(self.db.layout(), &cut.cut, self.value_range)?;
        stats.index_ms = ms(t);

        let scene = self.geometry(placement);
        let mut settings = self.settings(&ctx, &tools, cfg);
        let continues = self.continue_history(frame, placement, views, cfg, &mut settings);
        let pb_next = self.plan_prediction(placement, views, cfg, &mut settings);
        let t = Instant::now();
        let tf = self
            .tf
            .as_ref()
            .context("render: no transfer function set")?;
        let out = self.raycaster.render(
            &self.gpu,
            &RenderInputs {
                pool: &self.pool,
                index: &index,
                tf: &tf.table,
                scene: &scene,
                views,
                settings: &settings,
            },
        )?;
        stats.render_ms = ms(t);
        stats.samples = out.samples;
        stats.tiles = out.tiles;
        stats.tiles_ms = out.tiles_seconds * 1e3;

        // Visible nodes of this frame's feedback, pulled up to inner nodes
        // by the loader at the next refinement (G10 §5).
        stats.visible = out.feedback.iter().filter(|&&v| v != 0).count() as u64;
        self.cut_stats(&cut.stats, &mut stats);
        let predicted = settings.predict[0] > 1.5 && !out.prediction_reset;
        // A predicted frame's rays skip what lies before their last hit, so
        // its feedback under-reports: the loader keeps the last full
        // traversal's.
        if !predicted {
            self.last.push_back((index, out.feedback));
        }
        self.prediction = pb_next.map(|(k, since)| (k, if predicted { since } else { 0 }));
        let images = if cfg.reconstruction && self.reconstruct_on_gpu {
            out.images
        } else if cfg.reconstruction {
            let t = Instant::now();
            let images = self.reconstruct(frame, views, continues, out.images);
            stats.reconstruct_ms = ms(t);
            images
        } else {
            self.history.clear();
            self.history_key = None;
            out.images
        };
        let mut images = images;
        if cfg.overlay.show {
            cfg.overlay.check("render", cfg.refraction)?;
            // Tool geometry over every view (G10 §5), in front of the
            // volume: drawn after reconstruction, so no history holds it.
            let shapes = parallax_common::overlay::shapes(&cfg.overlay, &tools, &ctx);
            if !shapes.is_empty() {
                if self.overlay.is_none() {
                    self.overlay = Some(crate::overlay::OverlayRenderer::new(&self.gpu)?);
                }
                let depth = cfg.overlay.depth.then(|| {
                    let units_per_metre = 1.0 / placement.scale(ctx.extent);
                    (self.raycaster.depth_buffer(), units_per_metre)
                });
                let r = self.overlay.as_mut().expect("made above");
                let layers = r.draw(&self.gpu, &shapes, &cfg.overlay, views, depth)?;
                for (img, layer) in images.iter_mut().zip(&layers) {
                    crate::overlay::lay_over(img, layer);
                }
            }
        }
        stats.total_ms = ms(start);
        Ok(Frame {
            images,
            stats,
            predicted,
        })
    }

    /// Refines the cut for this frame's views (G08 §4, G10 §5) with the
    /// visibility feedback of the last frame, or of the last four
    /// sub-frames with reconstruction (a node is invisible only if they all
    /// missed it).
    fn refine(
        &mut self,
        frame: u64,
        views: &[View],
        placement: &Placement,
        cfg: &RenderConfig,
        windows: &[(f64, f64)],
    ) -> Result<crate::loader::FrameCut> {
        let tf = self
            .tf
            .as_ref()
            .context("render: no transfer function set")?;
        let table = if cfg.refraction {
            &tf.empty_refraction
        } else {
            &tf.empty
        };
        // Isosurfaces: a node can hold the surface only if its range
        // straddles the isovalue (G08 §4), whatever the transfer function.
        let iso = (cfg.mode == Mode::Iso).then_some(cfg.isovalue).flatten();
        let empty = |lo: f32, hi: f32| match iso {
            Some(v) => !(lo as f64 <= v && v <= hi as f64),
            None => {
                table.is_empty(lo as f64, hi as f64)
                    || outside_windows(windows, lo as f64, hi as f64)
            }
        };
        let keep = if cfg.reconstruction {
            SUBFRAMES as usize
        } else {
            1
        };
        while self.last.len() > keep {
            self.last.pop_front();
        }
        let feedbacks: Vec<(&SpatialIndex, &[u32])> = if self.last.len() == keep {
            self.last.iter().map(|(i, f)| (i, f.as_slice())).collect()
        } else {
            Vec::new()
        };
        let cut = self
            .loader
            .update_with_feedbacks(views, placement, &empty, &feedbacks);
        tracing::debug!(
            frame,
            nodes = cut.stats.nodes,
            uploads = cut.uploads.len(),
            reads = cut.requests.len(),
            culled_empty = cut.stats.culled_empty,
            culled_frustum = cut.stats.culled_frustum,
            culled_invisible = cut.stats.culled_invisible,
            held_back = ?cut.stats.held_back,
            "cut refined"
        );
        Ok(cut)
    }

    /// Uploads the cut's new bricks to the pool with their variance (for
    /// the prediction buffer's κ), and marks their empty macrocells.
    fn upload(
        &mut self,
        cut: &crate::loader::FrameCut,
        cfg: &RenderConfig,
        windows: &[(f64, f64)],
    ) -> Result<()> {
        let tf = self
            .tf
            .as_ref()
            .context("render: no transfer function set")?;
        let (v_lo, v_hi) = self.variance_range;
        let layered = !self.layers.is_empty();
        let fills: Vec<f32> = std::iter::once(self.value_range.0)
            .chain(self.layers.iter().map(|l| l.fill))
            .collect();
        // A macrocell is empty where every medium with data there is: the
        // volume's under its function and the band pickers' windows, each
        // layer's under its own.
        let layers = &self.layers;
        let empty = |ch: usize, lo: f64, hi: f64| match ch {
            0 => tf.empty.is_empty(lo, hi) || outside_windows(windows, lo, hi),
            k => layers[k - 1].empty.is_empty(lo, hi),
        };
        for u in &cut.uploads {
            let v = self.db.node(u.key).map_or(0.0, |n| n.variance);
            let norm = if v_hi > v_lo {
                (v - v_lo) / (v_hi - v_lo)
            } else {
                0.0
            };
            if layered {
                self.pool
                    .upload_layered(&self.gpu, u.slot, &u.data, &fills, norm);
            } else {
                self.pool.upload(
                    &self.gpu,
                    u.slot,
                    &u.data.values,
                    u.data.cells.as_deref(),
                    norm,
                );
            }
            if cfg.macrocells && !self.cells_stale {
                self.pool.mark_cells(u.slot, &empty);
            }
        }
        // A scene without macrocells pays nothing for them but the ranges
        // taken at upload; switched on, every resident brick is marked.
        if !cfg.macrocells {
            self.cells_stale = true;
        } else if std::mem::take(&mut self.cells_stale) {
            self.pool.mark_all_cells(&empty);
        }
        self.pool.flush_cells(&self.gpu);
        Ok(())
    }

    /// Frame reconstruction: whether this frame continues the history (the
    /// views, render settings, transfer function and tools the same, the
    /// placement moved, not jumped), and its sub-frame.
    fn continue_history(
        &mut self,
        frame: u64,
        placement: &Placement,
        views: &[View],
        cfg: &RenderConfig,
        settings: &mut RenderSettings,
    ) -> bool {
        if !cfg.reconstruction {
            return false;
        }
        settings.subframe = Some(subframe_of(frame));
        let key = HistoryKey {
            views: views.to_vec(),
            cfg: cfg.clone(),
            tf: self.tf_version(),
            tools: self.tools.0,
            placement: *placement,
        };
        let continues = self.history_key.as_ref().is_some_and(|k| k.continues(&key));
        self.history_key = Some(key);
        if self.reconstruct_on_gpu {
            self.history.clear();
            settings.reconstruct = Some(!continues);
        }
        continues
    }

    /// The prediction buffer (B10 §4): a full traversal when its contents
    /// do not belong to this view, and every α frames. Returns the key and
    /// frame count the next frame continues from.
    fn plan_prediction(
        &self,
        placement: &Placement,
        views: &[View],
        cfg: &RenderConfig,
        settings: &mut RenderSettings,
    ) -> Option<(HistoryKey, u32)> {
        if cfg.mode != Mode::Iso || !cfg.prediction {
            return None;
        }
        let key = HistoryKey {
            views: views.to_vec(),
            cfg: cfg.clone(),
            tf: None,
            tools: self.tools.0,
            placement: *placement,
        };
        let since = match &self.prediction {
            Some((k, c)) if k.continues(&key) && c + 1 < cfg.full_traversal_every => c + 1,
            _ => 0,
        };
        let window = PREDICTION_WINDOW_VOXELS * self.finest_voxel();
        settings.predict = [
            if since == 0 { 1.0 } else { 2.0 },
            window as f32,
            cfg.kappa[0] as f32,
            cfg.kappa[1] as f32,
        ];
        Some((key, since))
    }

    /// The cut's figures in the frame's statistics.
    fn cut_stats(&self, c: &crate::loader::CutStats, stats: &mut FrameStats) {
        stats.cut_nodes = c.nodes as u64;
        stats.cut_leaves_with_data = c.leaves_with_data as u64;
        stats.resident = c.gpu_resident as u64;
        stats.uploaded = c.uploaded as u64;
        stats.requested = c.requested as u64;
        stats.cache_hits = c.cache_hits;
        stats.cache_misses = c.cache_misses;
        stats.bytes_read = c.bytes_read;
        stats.cpu_bytes = c.cpu_bytes;
        stats.adequate = c.adequate && c.requested == 0 && self.loader.in_flight() == 0;
        stats.held_back = c.held_back.iter().copied().collect();
    }

    /// Frame reconstruction (G10 §5) on the CPU: the rendered sub-frame
    /// into each view's history, the rest filtered. The history starts
    /// anew unless this frame `continues` it.
    fn reconstruct(
        &mut self,
        frame: u64,
        views: &[View],
        continues: bool,
        rendered: Vec<Vec<[f32; 4]>>,
    ) -> Vec<Vec<[f32; 4]>> {
        if !continues || self.history.len() != views.len() {
            self.history = views
                .iter()
                .map(|v| ViewHistory::new(v.resolution[0], v.resolution[1]))
                .collect();
        }
        let k = subframe_of(frame);
        self.history
            .iter_mut()
            .zip(rendered)
            .map(|(h, img)| h.update(k, &img))
            .collect()
    }

    /// Renders until the cut stops changing (every leaf adequate, nothing
    /// left to read), at most `max_frames` times; returns the last frame.
    pub fn converge(
        &mut self,
        placement: &Placement,
        views: &[View],
        cfg: &RenderConfig,
        max_frames: usize,
    ) -> Result<Frame> {
        let sync = std::mem::replace(&mut self.sync_io, true);
        let mut last = None;
        for i in 0..max_frames.max(1) {
            let f = self.frame(i as u64, placement, views, cfg)?;
            let done = f.stats.adequate && f.stats.uploaded == 0;
            last = Some(f);
            if done {
                break;
            }
        }
        self.sync_io = sync;
        Ok(last.expect("at least one frame"))
    }
}

/// Whether the value range [lo, hi] misses one of the band pickers' value
/// windows (so a band picker that acts fully makes it transparent).
fn outside_windows(windows: &[(f64, f64)], lo: f64, hi: f64) -> bool {
    windows.iter().any(|&(b0, b3)| hi < b0 || lo > b3)
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Half the window, in source voxels, that a ray which hit the surface last
/// frame searches from before its last hit (B10 §4.4, local traversal).
pub const PREDICTION_WINDOW_VOXELS: f64 = 8.0;

/// What a view's reconstruction history (or prediction buffer) was made
/// under.
struct HistoryKey {
    views: Vec<View>,
    cfg: RenderConfig,
    tf: Option<u64>,
    tools: u64,
    placement: Placement,
}

impl HistoryKey {
    /// Largest change of the placement from one frame to the next that the
    /// filter follows as motion; more is a jump and restarts the history.
    const MAX_TURN_DEG: f64 = 10.0;
    const MAX_SHIFT: f64 = 0.1;

    /// Whether `next` continues this history: same views, settings,
    /// transfer function and tools, and a placement that moved, not jumped.
    fn continues(&self, next: &HistoryKey) -> bool {
        let (a, b) = (&self.placement, &next.placement);
        let turn = (0..3)
            .map(|i| (a.rotation_deg[i] - b.rotation_deg[i]).abs())
            .fold(0.0, f64::max);
        let shift = (0..3)
            .map(|i| (a.center[i] - b.center[i]).abs())
            .fold(0.0, f64::max);
        self.views == next.views
            && self.cfg == next.cfg
            && self.tf == next.tf
            && self.tools == next.tools
            && turn <= Self::MAX_TURN_DEG
            && shift <= Self::MAX_SHIFT * a.size
            && (b.size / a.size - 1.0).abs() <= Self::MAX_SHIFT
    }
}
