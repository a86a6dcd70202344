//! The adaptive loader: each frame, a view- and transfer-function-dependent
//! cut of the out-of-core octree, kept in a CPU level-2 cache and a GPU brick
//! pool, fed by asynchronous reads (G08 §4, G10 §5 "GPU cache and spatial
//! index" and "Visibility feedback and adaptive loader", L12 §4.2).
//!
//! Per frame ([`Loader::update`]):
//!
//! 1. Bricks the I/O threads finished since the last frame enter the CPU
//!    cache (never waiting for one).
//! 2. The last frame's visibility feedback, if any, is pulled up to inner
//!    nodes (G10 §5).
//! 3. The cut is refined from the root in order of projected voxel size,
//!    largest first, using for each node the finest requirement among the
//!    views (G08 §4, G10 §5, L12 §4.2). A node is a leaf of the cut when it
//!    is adequate, at the finest level, empty under the transfer function,
//!    outside every view frustum, invisible in the last feedback, or when its
//!    children cannot all be on the GPU this frame (data not in core, pool
//!    full, upload budget spent).
//! 4. The bricks the refinement wanted but did not find are requested, in
//!    priority order; requests queued earlier and no longer wanted are
//!    withdrawn.
//!
//! The returned [`FrameCut`] lists every node of the cut (for
//! [`crate::index::SpatialIndex::build`]), the bricks to copy into GPU slots
//! before rendering, and statistics.

mod cache;
mod feedback;
pub(crate) mod geometry;
mod io;
mod ranges;
mod resample;

use crate::geometry::{Geometry, SceneGeometry};
use crate::index::{CutNode, SpatialIndex, MAX_INDEX_NODES, NO_SLOT};
use crate::store::{Brick, NodeKey, OctreeDb};
use cache::{ByteLru, SlotPool};
use feedback::Visibility;
use geometry::FrameGeometry;
pub use geometry::LightField;
use io::{IoPool, Landed, Source};
use parallax_common::camera::{Placement, View};
use parallax_common::protocol::HeldBack;
use parallax_common::tf::{EmptinessTable, TransferFunction};
use ranges::SubtreeRanges;
pub use resample::Affine;
use serde::Serialize;
use std::collections::{BTreeSet, BinaryHeap, HashMap, HashSet, VecDeque};
use std::sync::Arc;

/// Budgets and policy of a [`Loader`].
#[derive(Clone, Debug, PartialEq)]
pub struct LoaderConfig {
    /// CPU level-2 cache of decoded bricks (LRU), bytes (G08 §4). Requests in
    /// flight are limited to what it can hold.
    pub cpu_budget_bytes: u64,
    /// GPU brick pool capacity in slots (LRU; the slots of the current cut are
    /// pinned) (G08 §4). At most 2^24 − 1 (the spatial index's slot field).
    pub gpu_slots: u32,
    /// Most bricks uploaded to the GPU per frame: a fast camera must not
    /// stall a frame (G08 §4 "the number of updated nodes per frame is
    /// generally small").
    pub upload_budget: usize,
    /// A node is adequate when one of its voxels projects to ≤ `accuracy`
    /// display pixels (G08 §4, L12 §4.2).
    pub accuracy: f64,
    /// Nodes whose voxel can hold most of a ray's light (optical depth
    /// above 1) are adequate only at
    /// `accuracy / opaque_detail` pixels (`render.opaque_detail`; 1: off).
    /// Which nodes those are comes from [`Loader::set_opacity`].
    pub opaque_detail: f64,
    /// G10 §5 visibility feedback culling.
    pub use_feedback: bool,
    /// View-frustum culling (on unless a test compares against it).
    pub frustum_culling: bool,
    /// I/O threads (at least one is started).
    pub io_threads: usize,
}

impl Default for LoaderConfig {
    fn default() -> Self {
        LoaderConfig {
            cpu_budget_bytes: 1 << 30,
            gpu_slots: 4096,
            upload_budget: 64,
            accuracy: 1.0,
            opaque_detail: 1.0,
            use_feedback: true,
            frustum_culling: true,
            io_threads: 2,
        }
    }
}

/// A brick the renderer copies into a GPU slot this frame, before rendering.
#[derive(Clone, Debug)]
pub struct Upload {
    pub slot: u32,
    pub key: NodeKey,
    /// (B+4)³ decoded values, x fastest, and the stored macrocell ranges.
    pub data: Arc<Brick>,
}

/// One frame's cut.
#[derive(Clone, Debug)]
pub struct FrameCut {
    /// Every node of the cut: inner nodes (`refined`) and leaves. Children of
    /// a refined node that lie outside the volume are not listed (the index
    /// makes them empty leaves).
    pub cut: HashMap<NodeKey, CutNode>,
    /// Bricks to copy into GPU slots before rendering this frame.
    pub uploads: Vec<Upload>,
    /// Reads posted this frame, highest priority first.
    pub requests: Vec<NodeKey>,
    pub stats: CutStats,
}

/// Figures of one frame (counters are per frame unless marked cumulative).
#[derive(Clone, Debug, Default, Serialize)]
pub struct CutStats {
    /// Nodes in the cut, inner and leaves.
    pub nodes: usize,
    pub leaves: usize,
    /// Leaves with a brick slot.
    pub leaves_with_data: usize,
    /// GPU slots in use (resident bricks, in the cut or cached).
    pub gpu_resident: usize,
    /// Bricks uploaded this frame.
    pub uploaded: usize,
    /// Reads posted this frame.
    pub requested: usize,
    /// Bytes in the CPU cache.
    pub cpu_bytes: u64,
    /// Compressed bytes read from disk since the loader started (cumulative).
    pub bytes_read: u64,
    /// Bricks the refinement needed on the GPU that were not there: found in
    /// the CPU cache (hits) or not (misses).
    pub cache_hits: u64,
    pub cache_misses: u64,
    /// Index nodes visible in the feedback used this frame (after pull-up).
    pub visible: usize,
    /// Nodes of the cut left unrefined because empty under the transfer
    /// function, outside every view frustum, or invisible in the feedback.
    pub culled_empty: usize,
    pub culled_frustum: usize,
    pub culled_invisible: usize,
    /// Every leaf is adequate (or at the finest level, or culled): nothing is
    /// held back by missing data or budgets.
    pub adequate: bool,
    /// Limits the user can raise that stopped refinement this frame.
    pub held_back: BTreeSet<HeldBack>,
}

/// How a node stands under this frame's transfer function.
#[derive(Clone, Copy, Debug)]
struct NodeClass {
    /// The node's own stored range (what its brick holds).
    min: f32,
    max: f32,
    /// Nothing in the subtree is visible under the transfer function, or the
    /// subtree stores no brick: a leaf, never refined, no data (G08 §4).
    culled_empty: bool,
    /// The node's own brick is stored and not empty: it needs a GPU slot
    /// when it is in the cut.
    needs_data: bool,
}

/// A node of the cut waiting to be refined.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    pixels: f64,
    seen: bool,
    key: NodeKey,
}

impl PartialEq for Candidate {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o).is_eq()
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Candidate {
    /// Largest projected voxel first; ties by key (coarse, low first) so the
    /// order is deterministic.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.pixels
            .total_cmp(&o.pixels)
            .then_with(|| o.key.cmp(&self.key))
    }
}

/// The bricks one blocked refinement waits for: children already in the
/// CPU cache and children still on disk. A refinement needs all of them in
/// core at once, so they are kept and requested together.
#[derive(Debug, Default)]
struct Group {
    cached: Vec<NodeKey>,
    missing: Vec<NodeKey>,
}

/// What one frame's refinement accumulates.
#[derive(Default)]
struct Build {
    cut: HashMap<NodeKey, CutNode>,
    uploads: Vec<Upload>,
    /// Blocked refinements, highest priority first.
    wanted: Vec<Group>,
    /// GPU slots the blocked refinements will need: not offered to
    /// lower-priority ones.
    reserved: usize,
    stats: CutStats,
}

/// A registered layer as the loader reads it.
pub struct LayerSource {
    pub db: Arc<OctreeDb>,
    /// Its transfer function's emptiness.
    pub empty: EmptinessTable,
    /// Where it lies in the scene volume (layer space → the volume's), for
    /// a layer on another grid; `None` on the volume's grid.
    pub transform: Option<Affine>,
    /// A label layer: resampled at the nearest voxel.
    pub nearest: bool,
}

/// The adaptive loader of one back-end process: one CPU cache, one GPU pool
/// and one cut for all of the process's views (G10 §5).
pub struct Loader {
    db: Arc<OctreeDb>,
    /// The scene volume's database, then its registered layers' (one
    /// traversal serves all: their octrees align, or they are resampled
    /// onto the volume's).
    sources: Arc<Vec<Source>>,
    cfg: LoaderConfig,
    geom: Geometry,
    ranges: SubtreeRanges,
    /// The layers' subtree ranges, in `sources` order after the volume.
    layer_ranges: Vec<Option<SubtreeRanges>>,
    l2: ByteLru,
    gpu: SlotPool,
    io: IoPool,
    /// Posted and not yet landed (queued or being read): never posted twice.
    in_flight: HashSet<NodeKey>,
    /// Bricks the CPU cache holds (all bricks have the same size).
    l2_bricks: usize,
    /// Bricks whose read failed: not asked for again.
    failed: HashSet<NodeKey>,
    errors: Vec<String>,
    bytes_read: u64,
    lightfield: Option<LightField>,
    /// The transfer function that says which nodes' voxels can be opaque
    /// (`LoaderConfig::opaque_detail`); `None`: none are.
    opacity: Option<TransferFunction>,
}

/// A CPU budget's shares: each placed layer keeps the decoded bricks it
/// read last (`recent` bytes each), and the CPU cache has the rest, in
/// bytes and in bricks of `stored_len` voxels of `channels` f32s.
fn cpu_shares(budget: u64, placed: u64, stored_len: usize, channels: u64) -> (u64, u64, usize) {
    let recent = (budget / resample::RECENT_SHARE).min(resample::RECENT_MOST);
    let l2_budget = budget - placed * recent;
    let brick_bytes = (stored_len * std::mem::size_of::<f32>()) as u64 * channels;
    let l2_bricks = (l2_budget / brick_bytes.max(1)).min(usize::MAX as u64) as usize;
    (recent, l2_budget, l2_bricks)
}

impl Loader {
    /// The transfer function whose extinction decides which nodes are held
    /// to `accuracy / detail` pixels, and `detail` (≥ 1; 1 or `None`: every
    /// node to `accuracy`). An isosurface passes `None`: its nodes are
    /// chosen by the isovalue.
    pub fn set_opacity(&mut self, detail: f64, tf: Option<&TransferFunction>) {
        self.cfg.opaque_detail = detail.max(1.0);
        if self.opacity.as_ref() != tf {
            self.opacity = tf.cloned();
        }
    }

    /// How many times finer than `accuracy` a node must be seen: the
    /// opaque detail where one of the node's voxels, along the edge its
    /// children halve (`Geometry::voxel_len`), has an optical depth above 1
    /// for some value in its subtree's range (what its descendants show,
    /// which the node's averages may have smoothed away), else 1.
    fn detail(&self, key: NodeKey) -> f64 {
        match (&self.opacity, self.ranges.get(key)) {
            (Some(tf), Some((lo, hi))) if self.cfg.opaque_detail > 1.0 => {
                let edge = self.geom.voxel_len(key.level as u32);
                let tau = tf.max_extinction_in(f64::from(lo), f64::from(hi));
                // The depth the kernel's opaque-segment refinement starts at.
                if tau * edge > crate::raycast::REFINE_DEPTH {
                    self.cfg.opaque_detail
                } else {
                    1.0
                }
            }
            _ => 1.0,
        }
    }

    /// The light field display the η > 0 views are shown on: their level
    /// of detail then follows the display's depth-dependent resolution
    /// s(z) = s0 + 2|z|·tan(Φ/2) (G10 §4) instead of the pixel grid.
    pub fn set_lightfield(&mut self, lightfield: Option<LightField>) {
        self.lightfield = lightfield;
    }

    /// The accuracy of the coming frames' refinement (the one multilevel
    /// sampling blends by).
    pub fn set_accuracy(&mut self, accuracy: f64) {
        self.cfg.accuracy = accuracy;
    }

    pub fn lightfield(&self) -> Option<LightField> {
        self.lightfield
    }

    /// Starts the loader and its I/O threads over an open database.
    pub fn new(db: Arc<OctreeDb>, cfg: LoaderConfig) -> Self {
        Self::with_layers(db, Vec::new(), cfg)
    }

    /// A loader over a scene volume and its registered layers, each with
    /// its transfer function's emptiness (fixed for the loader's life): on
    /// the same octree, or placed by an affine map and resampled onto the
    /// volume's bricks as they are read (`resample`). A node needs a GPU
    /// slot where any of them has data there that is not empty; it is read
    /// with every layer that has (never a layer's empty brick), and takes
    /// one slot.
    pub fn with_layers(db: Arc<OctreeDb>, layers: Vec<LayerSource>, cfg: LoaderConfig) -> Self {
        let layout = *db.layout();
        let geom = Geometry::new(layout, db.header.info.spacing);
        let ranges = SubtreeRanges::new(&db);
        // (A placed layer keeps its own, in `resample::Placed`.)
        let layer_ranges = layers
            .iter()
            .map(|l| l.transform.is_none().then(|| SubtreeRanges::new(&l.db)))
            .collect();
        let channels = 1 + layers.len() as u64;
        let placed = layers.iter().filter(|l| l.transform.is_some()).count() as u64;
        let (recent, l2_budget, l2_bricks) =
            cpu_shares(cfg.cpu_budget_bytes, placed, layout.stored_len(), channels);
        let slots = cfg.gpu_slots.min(NO_SLOT);
        let sources = Arc::new(
            std::iter::once(Source {
                db: db.clone(),
                empty: None,
                placed: None,
            })
            .chain(layers.into_iter().map(|l| Source {
                placed: l.transform.map(|t| {
                    resample::Placed::new(
                        l.db.clone(),
                        layout,
                        db.header.info.spacing,
                        t,
                        l.nearest,
                        recent,
                    )
                    .expect("an invertible layer transform (the renderer checks it)")
                }),
                db: l.db,
                empty: Some(l.empty),
            }))
            .collect::<Vec<_>>(),
        );
        let io = IoPool::new(sources.clone(), cfg.io_threads.max(1));
        Loader {
            sources,
            layer_ranges,
            l2: ByteLru::new(l2_budget),
            gpu: SlotPool::new(slots),
            io,
            db,
            cfg,
            geom,
            ranges,
            in_flight: HashSet::new(),
            l2_bricks,
            failed: HashSet::new(),
            errors: Vec::new(),
            bytes_read: 0,
            lightfield: None,
            opacity: None,
        }
    }

    /// A new CPU cache budget (`LoaderConfig::cpu_budget_bytes`), shared
    /// as at the start; the least recently used bricks go until it holds.
    /// A series' drawn step takes half the budget it was started with.
    pub fn set_cpu_budget(&mut self, bytes: u64) {
        let placed = self.sources.iter().filter(|s| s.placed.is_some()).count() as u64;
        let channels = self.sources.len() as u64;
        let (recent, l2_budget, l2_bricks) =
            cpu_shares(bytes, placed, self.db.layout().stored_len(), channels);
        for p in self.sources.iter().filter_map(|s| s.placed.as_ref()) {
            p.set_recent_budget(recent);
        }
        self.l2.set_budget(l2_budget);
        self.l2_bricks = l2_bricks;
        self.cfg.cpu_budget_bytes = bytes;
    }

    /// Turns view-frustum culling on or off (tests compare against it).
    pub fn set_frustum_culling(&mut self, on: bool) {
        self.cfg.frustum_culling = on;
    }

    pub fn config(&self) -> &LoaderConfig {
        &self.cfg
    }

    pub fn db(&self) -> &Arc<OctreeDb> {
        &self.db
    }

    /// One frame's refinement (G08 §4, G10 §5, L12 §4.2).
    ///
    /// Never blocks on I/O: reads and decoding run on the I/O threads, their
    /// results are picked up here at the next call, and refinement uses only
    /// what is resident. `empty(min, max)` says whether a value range is empty
    /// under the current transfer function (G08 §4's summed-area table test,
    /// e.g. [`parallax_common::tf::EmptinessTable::is_empty`]). `feedback` is
    /// the last frame's index and its visibility words (`feedback[i] != 0`:
    /// index node i was traversed with data), used when
    /// [`LoaderConfig::use_feedback`] is on.
    pub fn update(
        &mut self,
        views: &[View],
        placement: &Placement,
        empty: &dyn Fn(f32, f32) -> bool,
        feedback: Option<(&SpatialIndex, &[u32])>,
    ) -> FrameCut {
        let list: Vec<(&SpatialIndex, &[u32])> = feedback.into_iter().collect();
        self.update_with_feedbacks(views, placement, empty, &list)
    }

    /// [`Loader::update`] with the feedback of several recent frames: a node
    /// is invisible only if every one of them says so (frame reconstruction
    /// renders a quarter of the pixels each frame, so one frame's feedback
    /// alone would miss what the other sub-frames see).
    pub fn update_with_feedbacks(
        &mut self,
        views: &[View],
        placement: &Placement,
        empty: &dyn Fn(f32, f32) -> bool,
        feedbacks: &[(&SpatialIndex, &[u32])],
    ) -> FrameCut {
        self.drain();
        let vis = if self.cfg.use_feedback && !feedbacks.is_empty() {
            Visibility::from_feedbacks(feedbacks)
        } else {
            Visibility::none()
        };
        let frame = FrameGeometry::new(
            &SceneGeometry {
                geom: self.geom,
                placement: *placement,
            },
            views,
        )
        .with_lightfield(self.lightfield);
        self.gpu.begin_frame();
        let mut b = Build::default();
        b.stats.adequate = true;
        b.stats.visible = vis.visible;

        // The root must be resident before anything else (G08 §4: refinement
        // starts from the root every frame).
        let root = NodeKey::root();
        let rc = self.classify(root, empty);
        b.cut.insert(root, cut_node(&rc, None));
        let mut heap = BinaryHeap::new();
        if rc.culled_empty {
            b.stats.culled_empty += 1;
        } else {
            let ready = if rc.needs_data {
                let slot = self.root_slot(root, &mut b);
                b.cut.get_mut(&root).unwrap().slot = slot;
                slot.is_some()
            } else {
                true
            };
            if ready {
                heap.push(candidate(&frame, root, self.detail(root)));
            } else {
                b.stats.adequate = false;
            }
        }

        let leaf_level = self.geom.layout.leaf_level();
        let mut index_nodes = 1usize;
        while let Some(c) = heap.pop() {
            let key = c.key;
            if key.level as u32 >= leaf_level {
                continue; // nothing finer exists
            }
            if !c.seen && self.cfg.frustum_culling {
                b.stats.culled_frustum += 1;
                continue;
            }
            if c.pixels <= self.cfg.accuracy {
                continue; // adequate
            }
            if vis.is_invisible(key) {
                b.stats.culled_invisible += 1;
                continue;
            }
            let kids = self.geom.layout.child_count(key.level as u32);
            if index_nodes + kids > MAX_INDEX_NODES {
                // The spatial index addresses nodes with 16 bits.
                b.stats.adequate = false;
                b.stats.held_back.insert(HeldBack::IndexNodes);
                continue;
            }
            if self.refine(key, empty, &frame, &mut b, &mut heap) {
                index_nodes += kids;
            } else {
                b.stats.adequate = false;
            }
        }

        let requests = self.post(&b.wanted);
        let stats = &mut b.stats;
        stats.nodes = b.cut.len();
        stats.leaves = b.cut.values().filter(|n| !n.refined).count();
        stats.leaves_with_data = b
            .cut
            .values()
            .filter(|n| !n.refined && n.slot.is_some())
            .count();
        stats.gpu_resident = self.gpu.in_use();
        stats.uploaded = b.uploads.len();
        stats.requested = requests.len();
        stats.cpu_bytes = self.l2.bytes();
        stats.bytes_read = self.bytes_read;
        FrameCut {
            cut: b.cut,
            uploads: b.uploads,
            requests,
            stats: b.stats,
        }
    }

    /// Blocks until every posted request has landed in the CPU cache (for
    /// tests and benchmarks that render "until converged").
    pub fn wait_idle(&mut self) {
        self.drain();
        while !self.in_flight.is_empty() {
            match self.io.recv() {
                Ok(l) => self.land(l),
                Err(_) => {
                    // Every I/O thread is gone: nothing more will land.
                    self.in_flight.clear();
                    break;
                }
            }
        }
    }

    /// Reads the root's brick now, waiting for it: a loader on a new
    /// database (a series' next step) then draws the root's level from its
    /// first frame rather than nothing. A failed read is reported as any
    /// other (`errors`).
    pub fn load_root(&mut self) {
        let root = NodeKey::root();
        if self.l2.contains(root) || self.failed.contains(&root) {
            return;
        }
        let result = io::read_node(&self.sources, root).map_err(|e| format!("{e:#}"));
        self.land(Landed { key: root, result });
    }

    /// Reads ahead, for a series' next step: posts reads of `keys` (most
    /// wanted first) that are stored and not in the CPU cache, as far as
    /// the cache has room, in place of the reads an earlier call posted that
    /// no thread has started; the cached ones are touched. Nothing goes to
    /// the GPU. Returns the reads posted.
    pub fn prefetch(&mut self, keys: &[NodeKey]) -> usize {
        self.drain();
        let groups: Vec<Group> = keys
            .iter()
            .filter(|&&k| self.db.node(k).is_some_and(|r| r.is_stored()))
            .map(|&k| match self.l2.contains(k) {
                true => Group {
                    cached: vec![k],
                    missing: vec![],
                },
                false => Group {
                    cached: vec![],
                    missing: vec![k],
                },
            })
            .collect();
        self.post(&groups).len()
    }

    /// Whether a brick is in the CPU cache.
    pub fn has_brick(&self, key: NodeKey) -> bool {
        self.l2.contains(key)
    }

    /// A decoded brick from the CPU cache.
    pub fn brick_data(&self, key: NodeKey) -> Option<Arc<Brick>> {
        self.l2.peek(key).cloned()
    }

    /// The GPU slot a brick occupies, if resident.
    pub fn gpu_slot(&self, key: NodeKey) -> Option<u32> {
        self.gpu.slot(key)
    }

    /// Requests posted and not yet landed.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// Read errors since the last call (a failed brick is not asked for
    /// again; its parent stays a leaf).
    pub fn errors(&mut self) -> Vec<String> {
        self.drain();
        std::mem::take(&mut self.errors)
    }

    fn drain(&mut self) {
        while let Ok(l) = self.io.try_recv() {
            self.land(l);
        }
    }

    fn land(&mut self, l: Landed) {
        self.in_flight.remove(&l.key);
        match l.result {
            Ok((Some(brick), bytes)) => {
                self.bytes_read += bytes;
                self.l2.insert(l.key, Arc::new(brick));
            }
            Ok((None, _)) => {}
            Err(e) => {
                self.failed.insert(l.key);
                self.errors.push(e);
            }
        }
    }

    fn classify(&self, key: NodeKey, empty: &dyn Fn(f32, f32) -> bool) -> NodeClass {
        let rec = self.db.node(key);
        let culled_empty = match self.ranges.get(key) {
            Some((lo, hi)) => empty(lo, hi),
            None => true,
        };
        let (min, max) = rec.map_or((0.0, 0.0), |r| (r.min, r.max));
        let mut c = NodeClass {
            min,
            max,
            culled_empty,
            needs_data: !culled_empty && rec.is_some_and(|r| r.is_stored() && !empty(r.min, r.max)),
        };
        // Registered layers: the node is empty where every layer is, and
        // needs data where any has some (`io::read_node` reads those).
        for (s, ranges) in self.sources[1..].iter().zip(&self.layer_ranges) {
            let Some(e) = &s.empty else { continue };
            let Some(ranges) = ranges else {
                if let Some(p) = &s.placed {
                    let cover = p.cover(key, e);
                    c.culled_empty &= cover.culled;
                    c.needs_data |= cover.needs_data;
                }
                continue;
            };
            let culled = ranges
                .get(key)
                .is_none_or(|(lo, hi)| e.is_empty(lo as f64, hi as f64));
            c.culled_empty &= culled;
            c.needs_data |= !culled
                && s.db
                    .node(key)
                    .is_some_and(|r| r.is_stored() && !e.is_empty(r.min as f64, r.max as f64));
        }
        c
    }

    /// The root's slot, uploading it from the CPU cache or requesting it.
    fn root_slot(&mut self, root: NodeKey, b: &mut Build) -> Option<u32> {
        if let Some(s) = self.gpu.pin(root) {
            return Some(s);
        }
        if self.l2.contains(root) {
            b.stats.cache_hits += 1;
            if b.uploads.len() < self.cfg.upload_budget && self.gpu.available() > 0 {
                return self.upload(root, b);
            }
            b.wanted.push(Group {
                cached: vec![root],
                missing: vec![],
            });
        } else if !self.failed.contains(&root) {
            b.stats.cache_misses += 1;
            b.wanted.push(Group {
                cached: vec![],
                missing: vec![root],
            });
        }
        None
    }

    /// Gives a brick in the CPU cache a GPU slot and lists its upload.
    /// `None` if the brick has left the CPU cache or every slot is pinned
    /// (callers check both first; a `None` leaves the node a leaf).
    fn upload(&mut self, key: NodeKey, b: &mut Build) -> Option<u32> {
        let data = self.l2.get(key)?;
        let (slot, _evicted) = self.gpu.allocate(key)?;
        b.uploads.push(Upload { slot, key, data });
        Some(slot)
    }

    /// Refines `key` if all its existing non-empty children can be on the GPU
    /// this frame (G08 §4); otherwise posts the missing reads (unless the pool
    /// is full) and leaves the node a leaf.
    fn refine(
        &mut self,
        key: NodeKey,
        empty: &dyn Fn(f32, f32) -> bool,
        frame: &FrameGeometry,
        b: &mut Build,
        heap: &mut BinaryHeap<Candidate>,
    ) -> bool {
        let layout = self.geom.layout;
        let mut kids: Vec<(NodeKey, NodeClass)> = Vec::with_capacity(8);
        let (mut resident, mut cached, mut missing) = (0usize, Vec::new(), Vec::new());
        for ch in layout.children(key) {
            if !layout.contains(ch) {
                continue;
            }
            let cl = self.classify(ch, empty);
            if cl.needs_data {
                if self.gpu.slot(ch).is_some() {
                    resident += 1;
                } else if self.l2.contains(ch) {
                    cached.push(ch);
                } else if !self.failed.contains(&ch) {
                    missing.push(ch);
                } else {
                    return false; // unreadable: this node stays a leaf
                }
            }
            kids.push((ch, cl));
        }
        b.stats.cache_hits += cached.len() as u64;
        b.stats.cache_misses += missing.len() as u64;
        // Resident children are not pinned yet: they count as evictable in
        // `available` but will be pinned, so they cannot make room; nor can
        // the slots higher-priority blocked refinements are waiting for.
        let need = cached.len() + missing.len();
        if need > self.gpu.available().saturating_sub(resident + b.reserved) {
            b.stats.held_back.insert(HeldBack::GpuPool);
            return false; // the GPU pool is full: not even a request
        }
        // Pin every resident child before any allocation, so no allocation
        // below can evict a sibling this refinement counts on.
        for (ch, cl) in &kids {
            if cl.needs_data {
                self.gpu.pin(*ch);
            }
        }
        if !missing.is_empty() || b.uploads.len() + cached.len() > self.cfg.upload_budget {
            if missing.is_empty() {
                // Only this frame's upload budget stands in the way: upload
                // what it still allows now, the rest in the next frames, so
                // any budget of at least one brick refines the cut.
                b.stats.held_back.insert(HeldBack::UploadBudget);
                let room = self.cfg.upload_budget.saturating_sub(b.uploads.len());
                let now: Vec<NodeKey> = cached.drain(..room.min(cached.len())).collect();
                for ch in now {
                    if self.upload(ch, b).is_none() {
                        return false;
                    }
                }
            }
            // Not in core yet (never wait), or this frame's uploads are
            // spent: keep what is cached, fetch the rest.
            let need = cached.len() + missing.len();
            b.reserved += need;
            b.wanted.push(Group { cached, missing });
            return false;
        }
        let mut slots = Vec::with_capacity(kids.len());
        for (ch, cl) in &kids {
            slots.push(if cl.needs_data {
                match self.gpu.slot(*ch) {
                    Some(s) => Some(s),
                    None => match self.upload(*ch, b) {
                        Some(s) => Some(s),
                        None => return false,
                    },
                }
            } else {
                None
            });
        }
        for ((ch, cl), slot) in kids.into_iter().zip(slots) {
            b.cut.insert(ch, cut_node(&cl, slot));
            if cl.culled_empty {
                b.stats.culled_empty += 1;
            } else {
                heap.push(candidate(frame, ch, self.detail(ch)));
            }
        }
        b.cut.get_mut(&key).unwrap().refined = true;
        true
    }

    /// Posts this frame's reads (G08 §4: asynchronous, in priority order).
    ///
    /// Blocked refinements are taken highest priority first while the CPU
    /// cache can hold, at the same time, the children each of them already has
    /// in core, the reads it still needs, and the reads other threads are
    /// already performing: their cached children are marked recently used and
    /// their reads posted, so bricks landing later never evict a sibling set
    /// before it is complete. Queued reads still wanted are reordered, those
    /// no longer wanted are withdrawn, reads in progress are left alone.
    /// Returns the newly posted reads.
    fn post(&mut self, groups: &[Group]) -> Vec<NodeKey> {
        let in_flight = &mut self.in_flight;
        let failed = &self.failed;
        let l2_bricks = self.l2_bricks;
        let mut fresh = Vec::new();
        let mut keep = Vec::new();
        self.io.requeue(|queued| {
            let queued: HashSet<NodeKey> = queued.into_iter().collect();
            // Reads in progress land in the cache whoever wants them.
            let started: HashSet<NodeKey> = in_flight
                .iter()
                .filter(|k| !queued.contains(k))
                .copied()
                .collect();
            let mut room = l2_bricks.saturating_sub(started.len());
            let mut accepted = HashSet::new();
            let mut q = VecDeque::new();
            for g in groups {
                let need =
                    g.cached.len() + g.missing.iter().filter(|k| !started.contains(k)).count();
                if need > room || g.missing.iter().any(|k| failed.contains(k)) {
                    continue;
                }
                room -= need;
                keep.extend_from_slice(&g.cached);
                for &k in &g.missing {
                    accepted.insert(k);
                    if queued.contains(&k) {
                        q.push_back(k);
                    } else if !in_flight.contains(&k) {
                        in_flight.insert(k);
                        fresh.push(k);
                        q.push_back(k);
                    }
                }
            }
            for k in &queued {
                if !accepted.contains(k) {
                    in_flight.remove(k);
                }
            }
            q
        });
        for k in keep {
            self.l2.touch(k);
        }
        fresh
    }
}

fn cut_node(c: &NodeClass, slot: Option<u32>) -> CutNode {
    CutNode {
        refined: false,
        slot,
        min: c.min,
        max: c.max,
    }
}

/// A node to refine, its projected voxel times `detail` (so an opaque node
/// is compared with `accuracy / detail`, and refined before translucent
/// nodes of the same size).
fn candidate(frame: &FrameGeometry, key: NodeKey, detail: f64) -> Candidate {
    let a = frame.assess(key);
    Candidate {
        pixels: a.pixels * detail,
        seen: a.seen,
        key,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{self, ImportOptions};
    use crate::volume::{MemorySource, Volume, VoxelType};

    /// The state a CPU cache smaller than the pool and a camera that moved
    /// away and back leave behind: the pool is full; seven children of the
    /// root are still resident from earlier frames but have left the CPU
    /// cache, the oldest of them (child 1) is the least recently used brick
    /// of all; child 0 is in the CPU cache only. Refining the root must pin
    /// the resident children before it allocates a slot for child 0, or that
    /// allocation evicts child 1, which can then be found nowhere.
    #[test]
    fn refinement_pins_resident_siblings_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let vol = Volume::from_fn([64, 64, 64], [1.0; 3], VoxelType::U8, |i, j, k| {
            ((i * 7 + j * 3 + k * 5) % 50) as f32 + 100.0
        });
        let path = dir.path().join("v.pxo");
        let opts = ImportOptions {
            brick: 8,
            ..Default::default()
        };
        store::import(&mut MemorySource::new(&vol), &path, "test", &opts).unwrap();
        let db = Arc::new(OctreeDb::open(&path).unwrap());
        let side = db.layout().stored_len();
        let mut loader = Loader::new(
            db.clone(),
            LoaderConfig {
                cpu_budget_bytes: 64 << 20,
                gpu_slots: 10,
                upload_budget: 100,
                accuracy: 1e-6,
                opaque_detail: 1.0,
                use_feedback: false,
                frustum_culling: true,
                io_threads: 1,
            },
        );
        let root = NodeKey::root();
        let kids: Vec<_> = db.layout().children(root).collect();
        let far = |x| NodeKey::new(2, x, 3, 3);
        // Allocation order is recency order: child 1 oldest, then two
        // unrelated bricks, then children 2..7, then the root.
        loader.gpu.begin_frame();
        for k in [kids[1], far(0), far(1)]
            .into_iter()
            .chain(kids[2..].iter().copied())
            .chain([root])
        {
            loader.gpu.allocate(k).unwrap();
        }
        loader.gpu.begin_frame();
        assert_eq!(loader.gpu.available(), 10);
        for k in [root, kids[0]] {
            loader.l2.insert(
                k,
                Arc::new(Brick {
                    values: vec![100.0; side],
                    cells: None,
                    layered: None,
                }),
            );
        }
        let view = View::window([32, 32], [0.4, 0.4], [0.0, 0.0, 1.0]);
        let placement = Placement {
            center: [0.0; 3],
            rotation_deg: [0.0; 3],
            size: 0.3,
        };
        let f = loader.update(&[view], &placement, &|_, _| false, None);
        // The root is refined with every child on the GPU: child 0 uploaded
        // into a slot freed by an unrelated brick, the others kept.
        assert!(f.cut[&root].refined);
        for &k in &kids {
            assert!(f.cut[&k].slot.is_some(), "{k}");
        }
        assert_eq!(
            f.uploads.iter().map(|u| u.key).collect::<Vec<_>>(),
            vec![kids[0]]
        );
        assert_eq!(
            loader.gpu.slot(far(0)),
            None,
            "the oldest unrelated brick makes room"
        );
        assert!(loader.gpu.slot(far(1)).is_some());
    }
}
