//! The adaptive loader against real databases: convergence, level of detail,
//! empty-space, frustum and visibility culling, budgets, never blocking, and
//! read errors (G08 §4, G10 §5, L12 §4.2).

use parallax_backend::index::SpatialIndex;
use parallax_backend::loader::{FrameCut, Loader, LoaderConfig};
use parallax_backend::store::{self, ImportOptions};
use parallax_backend::store::{NodeKey, OctreeDb};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// 64³ voxels, bricks of 8 (L = 3: 1 + 8 + 64 + 512 nodes). x < 24 is 0,
/// the rest is 100..150 with structure.
const N: usize = 64;
const SOLID_FROM: usize = 24;

fn volume() -> Volume {
    Volume::from_fn([N, N, N], [1.0, 1.0, 1.0], VoxelType::U8, |i, j, k| {
        if i < SOLID_FROM {
            0.0
        } else {
            100.0 + ((i * 7 + j * 3 + k * 5) % 50) as f32
        }
    })
}

fn import(vol: &Volume, out: &Path, opts: ImportOptions) -> Arc<OctreeDb> {
    store::import(&mut MemorySource::new(vol), out, "loader test", &opts).unwrap();
    Arc::new(OctreeDb::open(out).unwrap())
}

fn db(dir: &Path) -> Arc<OctreeDb> {
    import(
        &volume(),
        &dir.join("v.pxo"),
        ImportOptions {
            brick: 8,
            ..Default::default()
        },
    )
}

fn placement() -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [0.0, 0.0, 0.0],
        size: 0.3,
    }
}

fn window(z: f64) -> View {
    View::window([64, 64], [0.4, 0.4], [0.0, 0.0, z])
}

fn config(accuracy: f64) -> LoaderConfig {
    LoaderConfig {
        cpu_budget_bytes: 64 << 20,
        gpu_slots: 1000,
        upload_budget: 1000,
        accuracy,
        opaque_detail: 1.0,
        use_feedback: false,
        frustum_culling: true,
        io_threads: 2,
    }
}

fn never_empty(_: f32, _: f32) -> bool {
    false
}

/// Below 50 is transparent.
fn below_50(_: f32, max: f32) -> bool {
    max < 50.0
}

/// The renderer's side of the brick pool: what each slot holds.
#[derive(Default)]
struct Pool {
    slots: HashMap<u32, NodeKey>,
}

impl Pool {
    /// Applies a frame's uploads, then checks the frame: slots within the
    /// pool, every slot of the cut holds that node's brick, no slot twice, a
    /// proper tree, every refined node's non-empty stored children with data,
    /// and an index can be built.
    fn apply(
        &mut self,
        f: &FrameCut,
        db: &OctreeDb,
        empty: &dyn Fn(f32, f32) -> bool,
        gpu_slots: u32,
    ) {
        let side = db.layout().stored_side();
        for u in &f.uploads {
            assert!(u.slot < gpu_slots, "slot {} of {gpu_slots}", u.slot);
            assert_eq!(u.data.values.len(), side * side * side);
            self.slots.insert(u.slot, u.key);
        }
        assert!(f.stats.gpu_resident <= gpu_slots as usize);
        let mut used = HashSet::new();
        for (k, n) in &f.cut {
            if let Some(s) = n.slot {
                assert_eq!(self.slots.get(&s), Some(k), "slot {s} of {k}");
                assert!(used.insert(s), "slot {s} twice");
            }
            if let Some(p) = db.layout().parent(*k) {
                assert!(
                    f.cut.get(&p).is_some_and(|p| p.refined),
                    "{k}: parent not refined"
                );
            }
            if n.refined {
                for c in db.layout().children(*k) {
                    if !db.layout().contains(c) {
                        continue;
                    }
                    let cn = f.cut.get(&c).unwrap_or_else(|| panic!("{c} missing"));
                    let rec = db.node(c).unwrap();
                    if rec.is_stored() && !empty(rec.min, rec.max) {
                        assert!(cn.slot.is_some(), "{c}: non-empty child without data");
                    }
                }
            }
        }
        assert!(f.cut.contains_key(&NodeKey::root()));
        assert_eq!(f.stats.nodes, f.cut.len());
        assert_eq!(f.stats.uploaded, f.uploads.len());
        let index = SpatialIndex::build(
            db.layout(),
            &f.cut,
            (db.summary.value_min, db.summary.value_max),
        )
        .unwrap();
        let refined = f.cut.values().filter(|n| n.refined).count();
        assert_eq!(index.len(), 1 + 8 * refined);
    }
}

/// Update, check, wait for the reads, until a frame is adequate and neither
/// uploads nor requests anything.
fn converge(
    loader: &mut Loader,
    pool: &mut Pool,
    views: &[View],
    empty: &dyn Fn(f32, f32) -> bool,
    max_frames: usize,
) -> (FrameCut, usize) {
    let db = loader.db().clone();
    let slots = loader.config().gpu_slots;
    for frame in 0..max_frames {
        let f = loader.update(views, &placement(), empty, None);
        pool.apply(&f, &db, empty, slots);
        if f.stats.adequate && f.uploads.is_empty() && f.requests.is_empty() {
            return (f, frame);
        }
        loader.wait_idle();
    }
    panic!("no stable cut after {max_frames} frames");
}

fn leaf_level(db: &OctreeDb) -> u8 {
    db.layout().leaf_level() as u8
}

#[test]
fn first_update_never_blocks() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let mut loader = Loader::new(db.clone(), config(1.0));
    let t = Instant::now();
    let f = loader.update(&[window(1.0)], &placement(), &never_empty, None);
    assert!(t.elapsed() < Duration::from_millis(500));
    assert_eq!(f.cut.len(), 1);
    let root = f.cut[&NodeKey::root()];
    assert!(!root.refined);
    assert_eq!(root.slot, None);
    assert_eq!(f.requests, vec![NodeKey::root()]);
    assert_eq!(f.stats.requested, 1);
    assert_eq!(f.stats.cache_misses, 1);
    assert!(f.uploads.is_empty());
    assert!(!f.stats.adequate);
    // A second update does not post the root again while it is in flight
    // (or, if it has landed, uploads it).
    let g = loader.update(&[window(1.0)], &placement(), &never_empty, None);
    assert!(!g.requests.contains(&NodeKey::root()));
    loader.wait_idle();
    assert!(loader.brick_data(NodeKey::root()).is_some());
    assert_eq!(loader.in_flight(), 0);
    assert!(loader.errors().is_empty());
}

#[test]
fn converges_to_the_finest_level_with_tiny_accuracy() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let leaf = leaf_level(&db);
    assert_eq!(leaf, 3);
    for (empty, name) in [
        (&never_empty as &dyn Fn(f32, f32) -> bool, "none"),
        (&below_50, "below 50"),
    ] {
        let mut loader = Loader::new(db.clone(), config(1e-6));
        let mut pool = Pool::default();
        let (f, frames) = converge(&mut loader, &mut pool, &[window(1.0)], empty, 20);
        // one level per frame: root, then levels 1, 2, 3
        assert!(frames <= 6, "{name}: {frames} frames");
        let non_empty_leaf_bricks = db
            .nodes
            .iter()
            .filter(|r| r.key.level == leaf && r.is_stored() && !empty(r.min, r.max))
            .count();
        let with_data: Vec<_> = f
            .cut
            .iter()
            .filter(|(_, n)| !n.refined && n.slot.is_some())
            .collect();
        assert!(with_data.iter().all(|(k, _)| k.level == leaf), "{name}");
        assert_eq!(with_data.len(), non_empty_leaf_bricks, "{name}");
        assert_eq!(f.stats.leaves_with_data, non_empty_leaf_bricks);
        // every leaf not at the finest level is an empty one
        assert!(f
            .cut
            .iter()
            .filter(|(k, n)| !n.refined && k.level < leaf)
            .all(|(_, n)| n.slot.is_none()));
        if name == "none" {
            assert_eq!(non_empty_leaf_bricks, 512);
            assert_eq!(f.stats.nodes, 585);
            assert_eq!(f.stats.leaves, 512);
            assert_eq!(f.stats.culled_empty, 0);
        } else {
            // leaf x bricks 0 and 1 hold only zeros (overlap included):
            // 8·8·2 empty leaf bricks, all under the 4·4 level-2 nodes of x
            // brick 0 (source x < 20), which stay empty leaves
            assert_eq!(non_empty_leaf_bricks, 512 - 128);
            assert_eq!(f.stats.culled_empty, 16);
            assert_eq!(f.stats.nodes, 1 + 8 + 64 + 8 * 48);
        }
        // Resident: the whole cut's data (inner nodes keep theirs).
        let with_slot = f.cut.values().filter(|n| n.slot.is_some()).count();
        assert_eq!(f.stats.gpu_resident, with_slot);
        assert!(f.stats.adequate);
        // Stable: the next frame is the same cut and costs nothing.
        let g = loader.update(&[window(1.0)], &placement(), empty, None);
        assert_eq!(g.cut, f.cut);
        assert!(g.uploads.is_empty() && g.requests.is_empty());
        assert_eq!(g.stats.cache_hits + g.stats.cache_misses, 0);
        assert_eq!(g.stats.bytes_read, f.stats.bytes_read);
    }
}

#[test]
fn a_close_eye_gets_a_finer_cut_than_a_far_one() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let mut cuts = Vec::new();
    for z in [0.4, 10.0] {
        let mut loader = Loader::new(db.clone(), config(2.0));
        let mut pool = Pool::default();
        let (f, _) = converge(&mut loader, &mut pool, &[window(z)], &never_empty, 20);
        cuts.push(f);
    }
    let (near, far) = (&cuts[0], &cuts[1]);
    let deepest = |f: &FrameCut| f.cut.keys().map(|k| k.level).max().unwrap();
    // Far: level-2 voxels are 4 · 0.3/64 m on 0.4/64 m pixels, ≈ 1.5 px ≤ 2.
    assert_eq!(deepest(far), 2);
    assert_eq!(far.stats.nodes, 1 + 8 + 64);
    // Near: the front level-2 nodes are ≈ 2.4 px and get refined.
    assert_eq!(deepest(near), 3);
    assert!(
        near.stats.nodes > far.stats.nodes + 8,
        "{} vs {}",
        near.stats.nodes,
        far.stats.nodes
    );
    assert!(near.stats.bytes_read > far.stats.bytes_read);
}

#[test]
fn empty_bricks_are_never_read() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let mut read = Vec::new();
    for empty in [&never_empty as &dyn Fn(f32, f32) -> bool, &below_50] {
        let mut loader = Loader::new(db.clone(), config(1e-6));
        let mut pool = Pool::default();
        let mut requested = HashSet::new();
        let mut f;
        let mut frames = 0;
        loop {
            f = loader.update(&[window(1.0)], &placement(), empty, None);
            pool.apply(&f, &db, empty, 1000);
            for k in &f.requests {
                assert!(requested.insert(*k), "{k} requested twice");
            }
            if f.stats.adequate && f.requests.is_empty() && f.uploads.is_empty() {
                break;
            }
            loader.wait_idle();
            frames += 1;
            assert!(frames < 20);
        }
        for k in &requested {
            let r = db.node(*k).unwrap();
            assert!(!empty(r.min, r.max), "{k} is empty but was read");
        }
        let stored_bytes = |keys: &HashSet<NodeKey>| {
            keys.iter()
                .map(|k| db.node(*k).unwrap().len as u64)
                .sum::<u64>()
        };
        assert_eq!(f.stats.bytes_read, stored_bytes(&requested));
        read.push((f.stats.bytes_read, requested));
    }
    let (all_bytes, all_keys) = &read[0];
    let (culled_bytes, culled_keys) = &read[1];
    // without culling every stored brick is read once
    assert_eq!(
        all_keys.len(),
        db.nodes.iter().filter(|r| r.is_stored()).count()
    );
    assert!(*culled_bytes < *all_bytes);
    // the zero region (leaf x bricks 0, 1; level-2 x brick 0) is never read
    for k in all_keys {
        let zero = (k.level == 3 && k.x < 2) || (k.level == 2 && k.x == 0);
        assert_eq!(culled_keys.contains(k), !zero, "{k}");
    }
    assert_eq!(culled_keys.len(), all_keys.len() - 128 - 16);
}

#[test]
fn a_bright_detail_under_dropped_parents_is_still_reached() {
    // One bright voxel: its leaf bricks are stored, every coarser level
    // averages it below the import threshold and is dropped.
    let vol = Volume::from_fn([N, N, N], [1.0; 3], VoxelType::U8, |i, j, k| {
        if (i, j, k) == (43, 43, 43) {
            255.0
        } else {
            0.0
        }
    });
    let dir = tempfile::tempdir().unwrap();
    let db = import(
        &vol,
        &dir.path().join("dot.pxo"),
        ImportOptions {
            brick: 8,
            empty_below: Some(100.0),
            ..Default::default()
        },
    );
    assert!(!db.node(NodeKey::root()).unwrap().is_stored());
    let owner = NodeKey::new(3, 5, 5, 5);
    assert!(db.node(owner).unwrap().is_stored());
    let mut loader = Loader::new(db.clone(), config(1e-6));
    let mut pool = Pool::default();
    let (f, _) = converge(&mut loader, &mut pool, &[window(1.0)], &never_empty, 20);
    assert!(f.cut[&owner].slot.is_some());
    assert!(f.cut[&NodeKey::root()].refined && f.cut[&NodeKey::root()].slot.is_none());
    let stored_leaves = db.nodes.iter().filter(|r| r.is_stored()).count();
    assert_eq!(f.stats.leaves_with_data, stored_leaves);
    assert_eq!(
        loader
            .brick_data(owner)
            .unwrap()
            .values
            .iter()
            .cloned()
            .fold(0.0, f32::max),
        255.0
    );
}

#[test]
fn gpu_pool_budget_holds_and_the_cut_stays_valid() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let cfg = LoaderConfig {
        gpu_slots: 20,
        ..config(1e-6)
    };
    let mut loader = Loader::new(db.clone(), cfg);
    let mut pool = Pool::default();
    let mut last = None;
    for _ in 0..12 {
        let f = loader.update(&[window(1.0)], &placement(), &never_empty, None);
        pool.apply(&f, &db, &never_empty, 20);
        assert!(f.stats.gpu_resident <= 20);
        loader.wait_idle();
        last = Some(f);
    }
    let f = last.unwrap();
    // root + its 8 children + the 8 children of one of them = 17 slots; the
    // next refinement would need 8 more than the 3 left.
    assert_eq!(f.stats.nodes, 17);
    assert_eq!(f.stats.gpu_resident, 17);
    assert!(!f.stats.adequate);
    // … and the frame names the full pool as the reason.
    assert!(
        f.stats
            .held_back
            .contains(&parallax_common::protocol::HeldBack::GpuPool),
        "{:?}",
        f.stats.held_back
    );
    // A full pool posts no reads it could not use.
    assert!(f.requests.is_empty() && loader.in_flight() == 0);

    // Moving the eye evicts least recently used bricks, still within 20.
    for x in [-0.3, 0.3, 0.0] {
        for _ in 0..4 {
            let v = View::window([64, 64], [0.4, 0.4], [x, 0.0, 0.3]);
            let f = loader.update(&[v], &placement(), &never_empty, None);
            pool.apply(&f, &db, &never_empty, 20);
            assert!(f.stats.gpu_resident <= 20);
            loader.wait_idle();
        }
    }
}

#[test]
fn cpu_cache_budget_holds_across_frames() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let brick = (db.layout().stored_len() * 4) as u64;
    let budget = 12 * brick;
    let cfg = LoaderConfig {
        cpu_budget_bytes: budget,
        ..config(1e-6)
    };
    let mut loader = Loader::new(db.clone(), cfg);
    let mut pool = Pool::default();
    let mut converged = None;
    for frame in 0..300 {
        let f = loader.update(&[window(1.0)], &placement(), &never_empty, None);
        pool.apply(&f, &db, &never_empty, 1000);
        assert!(
            f.stats.cpu_bytes <= budget,
            "frame {frame}: {} > {budget}",
            f.stats.cpu_bytes
        );
        assert!(f.requests.len() <= 12);
        if f.stats.adequate && f.requests.is_empty() && f.uploads.is_empty() {
            converged = Some((frame, f));
            break;
        }
        loader.wait_idle();
    }
    let (frames, f) = converged.expect("converges with a 12-brick CPU cache");
    assert_eq!(f.stats.nodes, 585);
    // 73 refinements of 8 children, one per frame (a sibling set needs 8 of
    // the 12 bricks): root read, root uploaded, then 73 refinements
    assert_eq!(frames, 75);
    // sibling sets are fetched together and kept until uploaded: no brick
    // is read twice
    let stored: u64 = db.nodes.iter().map(|r| r.len as u64).sum();
    assert_eq!(f.stats.bytes_read, stored);
    assert!(loader.errors().is_empty());
}

#[test]
fn uploads_per_frame_stay_within_budget() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let cfg = LoaderConfig {
        upload_budget: 10,
        ..config(1e-6)
    };
    let mut loader = Loader::new(db.clone(), cfg);
    let mut pool = Pool::default();
    let mut total = 0;
    let mut frames = 0;
    loop {
        let f = loader.update(&[window(1.0)], &placement(), &never_empty, None);
        pool.apply(&f, &db, &never_empty, 1000);
        assert!(f.uploads.len() <= 10);
        total += f.uploads.len();
        if f.stats.adequate && f.requests.is_empty() && f.uploads.is_empty() {
            assert_eq!(f.stats.nodes, 585);
            break;
        }
        loader.wait_idle();
        frames += 1;
        assert!(frames < 100);
    }
    // every node uploaded exactly once, at most 10 a frame (a sibling set
    // that does not fit what is left of a frame's budget is uploaded over
    // two frames)
    assert_eq!(total, 585);
    assert!(frames >= 585 / 10);
}

#[test]
fn feedback_keeps_the_invisible_half_coarse() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let range = (db.summary.value_min, db.summary.value_max);
    let mut loader = Loader::new(
        db.clone(),
        LoaderConfig {
            use_feedback: true,
            frustum_culling: true,
            ..config(1e-6)
        },
    );
    let mut pool = Pool::default();
    let (full, _) = converge(&mut loader, &mut pool, &[window(1.0)], &never_empty, 20);
    assert_eq!(full.stats.nodes, 585);
    // The renderer saw only the leaves in the left half (x < ½ of the domain).
    let left = |k: &NodeKey| (k.x as f64 + 0.5) / (1u64 << k.level) as f64 <= 0.5;
    let mut index = SpatialIndex::build(db.layout(), &full.cut, range).unwrap();
    let mut frame = full;
    for round in 0..3 {
        let words: Vec<u32> = index
            .keys
            .iter()
            .zip(&index.nodes)
            .map(|(k, n)| (n.first_child().is_none() && n.slot().is_some() && left(k)) as u32)
            .collect();
        let f = loader.update(
            &[window(1.0)],
            &placement(),
            &never_empty,
            Some((&index, &words)),
        );
        pool.apply(&f, &db, &never_empty, 1000);
        // the right half of the root stays unrefined: 1 + 8 + 4·8 + 32·8
        assert_eq!(f.stats.nodes, 1 + 8 + 32 + 256, "round {round}");
        assert!(f
            .cut
            .iter()
            .filter(|(_, n)| n.refined)
            .all(|(k, _)| k.level == 0 || left(k)));
        assert_eq!(f.stats.culled_invisible, 4);
        assert!(f.stats.adequate);
        assert!(f.uploads.is_empty() && f.requests.is_empty());
        if round == 0 {
            // pulled up: root, 4 left level-1 nodes, 32 level-2, 256 leaves
            assert_eq!(f.stats.visible, 1 + 4 + 32 + 256);
            assert!(f.stats.nodes < frame.stats.nodes);
        }
        index = SpatialIndex::build(db.layout(), &f.cut, range).unwrap();
        frame = f;
    }
    // The same feedback with culling off changes nothing.
    let mut plain = Loader::new(db.clone(), config(1e-6));
    let mut pool = Pool::default();
    converge(&mut plain, &mut pool, &[window(1.0)], &never_empty, 20);
    let words = vec![0u32; index.len()];
    let f = plain.update(
        &[window(1.0)],
        &placement(),
        &never_empty,
        Some((&index, &words)),
    );
    assert_eq!(f.stats.nodes, 585);
    assert_eq!(f.stats.culled_invisible, 0);
    let _ = frame;
}

#[test]
fn a_view_looking_away_culls_everything_below_the_root() {
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let mut away = window(1.0);
    away.region = [5.0, 5.0, 0.4, 0.4];
    let mut loader = Loader::new(db.clone(), config(1e-6));
    let mut pool = Pool::default();
    let (f, _) = converge(&mut loader, &mut pool, &[away], &never_empty, 10);
    assert_eq!(f.stats.nodes, 1);
    assert!(f.cut[&NodeKey::root()].slot.is_some());
    assert_eq!(f.stats.culled_frustum, 1);
    assert_eq!(
        f.stats.bytes_read,
        db.node(NodeKey::root()).unwrap().len as u64
    );
    // With a second view that does look at the volume, the finest
    // requirement wins (G10 §5).
    let (g, _) = converge(
        &mut loader,
        &mut pool,
        &[away, window(1.0)],
        &never_empty,
        10,
    );
    assert_eq!(g.stats.nodes, 585);
    // η > 0 views are culled by the volume their rays sweep: none of the
    // aside view's rays reach the volume, all of the ahead view's may.
    away.eta = 1.0;
    away.eye = [0.2, 0.0, 1.2];
    let h = loader.update(&[away], &placement(), &never_empty, None);
    assert_eq!(h.stats.culled_frustum, 1);
    assert_eq!(h.stats.nodes, 1);
    let mut ahead = window(1.0);
    ahead.eta = 1.0;
    ahead.eye = [0.2, 0.0, 1.2];
    let (k, _) = converge(&mut loader, &mut pool, &[ahead], &never_empty, 10);
    assert_eq!(k.stats.culled_frustum, 0);
    assert!(k.stats.nodes > 1);
}

#[test]
fn read_errors_are_reported_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.pxo");
    let db0 = import(
        &volume(),
        &path,
        ImportOptions {
            brick: 8,
            ..Default::default()
        },
    );
    // Corrupt one level-1 brick in the file.
    let bad = NodeKey::new(1, 1, 0, 0);
    let rec = *db0.node(bad).unwrap();
    drop(db0);
    let mut bytes = std::fs::read(&path).unwrap();
    for b in &mut bytes[rec.offset as usize..rec.offset as usize + 8] {
        *b ^= 0xA5;
    }
    std::fs::write(&path, bytes).unwrap();
    let db = Arc::new(OctreeDb::open(&path).unwrap());
    let mut loader = Loader::new(db.clone(), config(1e-6));
    let mut errors = Vec::new();
    for _ in 0..6 {
        let f = loader.update(&[window(1.0)], &placement(), &never_empty, None);
        // the root cannot be refined without its corrupt child
        assert!(f.stats.nodes == 1);
        loader.wait_idle();
        errors.extend(loader.errors());
    }
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(errors[0].contains("level 1 (1, 0, 0)"), "{}", errors[0]);
}

/// A tiny upload budget still refines the whole cut: a sibling set is
/// uploaded over several frames (4 bricks a frame here), and the frame says
/// that the budget held it back.
#[test]
fn an_upload_budget_below_a_sibling_set_still_converges() {
    use parallax_common::protocol::HeldBack;
    let dir = tempfile::tempdir().unwrap();
    let db = db(dir.path());
    let cfg = LoaderConfig {
        upload_budget: 4,
        ..config(1e-6)
    };
    let mut loader = Loader::new(db.clone(), cfg);
    let mut pool = Pool::default();
    let mut held = false;
    let mut total = 0;
    for frame in 0..400 {
        let f = loader.update(&[window(1.0)], &placement(), &never_empty, None);
        pool.apply(&f, &db, &never_empty, 1000);
        assert!(f.uploads.len() <= 4, "frame {frame}: {}", f.uploads.len());
        total += f.uploads.len();
        held |= f.stats.held_back.contains(&HeldBack::UploadBudget);
        if f.stats.adequate && f.requests.is_empty() && f.uploads.is_empty() {
            assert_eq!(f.stats.nodes, 585);
            assert!(f.stats.held_back.is_empty());
            // Every node uploaded once, 4 a frame: at least 585 / 4 frames.
            assert_eq!(total, 585);
            assert!(frame >= 585 / 4, "{frame} frames");
            assert!(held);
            return;
        }
        loader.wait_idle();
    }
    panic!("an upload budget of 4 never converged");
}
