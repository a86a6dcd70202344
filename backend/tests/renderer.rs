//! The whole back-end renderer (`Renderer`: loader, caches, spatial index,
//! GPU ray caster) measured against the exact integral, against itself under
//! coarser settings, across views sharing one cache, under budgets far
//! smaller than the data, and on degenerate input. Every test prints the
//! figures it asserts on.

mod support;
use parallax_backend::data::{self, synth_value, write_synth, SynthKind};
use parallax_backend::index::MAX_INDEX_NODES;
use parallax_backend::loader::{Loader, LoaderConfig};
use parallax_backend::raycast::BrickPool;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::render::{Frame, Renderer};
use parallax_backend::store::{self, ImportOptions};
use parallax_backend::store::{BrickEncoding, NodeKey, OctreeDb};
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Interpolation, RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, EmptinessTable, PreintTable, TransferFunction};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;
use support::{
    assert_valid, exact_at, exact_config, import_volume, marschner_lobb, mean_alpha, translucent,
};

const COLIN27: &str = "/usr/share/mricron/templates/ch2.nii.gz";

fn configs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

/// Colin27 on the desktop display, face to the viewer (configs/scenes).
fn colin_placement() -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [-90.0, 180.0, 0.0],
        size: 0.25,
    }
}

fn centred(size: f64) -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [20.0, 35.0, 0.0],
        size,
    }
}

fn renderer(db: &Path, tf: &TransferFunction, cfg: &RenderConfig) -> Renderer {
    let mut r = Renderer::new(db, cfg).unwrap();
    r.set_transfer_function(1, tf).unwrap();
    r
}

/// Renders with every read waited for until the cut is stable (as
/// `Renderer::converge`), also returning the frame count and the bricks
/// uploaded over all frames.
fn converge_counting(
    r: &mut Renderer,
    placement: &Placement,
    views: &[View],
    cfg: &RenderConfig,
    max_frames: usize,
) -> (Frame, usize, u64) {
    r.sync_io = true;
    let mut uploads = 0;
    for i in 0..max_frames {
        let f = r.frame(i as u64, placement, views, cfg).unwrap();
        uploads += f.stats.uploaded;
        if f.stats.adequate && f.stats.uploaded == 0 {
            return (f, i + 1, uploads);
        }
    }
    panic!("no stable cut after {max_frames} frames");
}

/// RMSE and max abs difference over every channel of every pixel.
fn diff_ref(a: &[[f32; 4]], b: &[[f64; 4]]) -> (f64, f64) {
    support::error(a, b)
}

fn diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> (f64, f64) {
    let b: Vec<[f64; 4]> = b.iter().map(|p| p.map(|x| x as f64)).collect();
    diff_ref(a, &b)
}

fn reference_image(
    vol: &Volume,
    tf: &TransferFunction,
    placement: &Placement,
    view: &View,
    tol: f64,
) -> Vec<[f64; 4]> {
    reference::render(vol, tf, placement, view, Tolerance { abs: tol })
}

/// Σ stored length of `keys`.
fn stored_bytes(db: &OctreeDb, keys: &HashSet<NodeKey>) -> u64 {
    keys.iter().map(|k| db.node(*k).unwrap().len as u64).sum()
}

// ---------------------------------------------------------------------------

#[test]
fn colin27_matches_the_reference_integral() {
    let path = Path::new(COLIN27);
    if !path.exists() {
        eprintln!("SKIPPED: {COLIN27} is not installed (apt: mricron-data)");
        return;
    }
    let t = Instant::now();
    let vol = Volume::read_all(data::open(path, None).unwrap().as_mut()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("colin27.pxo");
    let rep = store::import(
        data::open(path, None).unwrap().as_mut(),
        &db,
        COLIN27,
        &ImportOptions {
            brick: 32,
            encoding: BrickEncoding::F32,
            ..Default::default()
        },
    )
    .unwrap();
    eprintln!(
        "colin27 {:?}, spacing {:?}: {} nodes, {} stored ({:.1} s)",
        vol.info.dims,
        vol.info.spacing,
        rep.nodes,
        rep.stored,
        t.elapsed().as_secs_f64()
    );
    let tf = TransferFunction::load(configs().join("tf/colin27-brain.toml")).unwrap();
    let cfg = exact_config();
    let placement = colin_placement();
    let view = View::window([64, 48], [0.4, 0.3], [0.0, 0.0, 0.8]);
    let mut r = renderer(&db, &tf, &cfg);
    let t = Instant::now();
    let f = r.converge(&placement, &[view], &cfg, 20).unwrap();
    let gpu_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let want = reference_image(&vol, &tf, &placement, &view, 1e-6);
    let ref_s = t.elapsed().as_secs_f64();
    let img = &f.images[0];
    let (e, mx) = diff_ref(img, &want);
    let ma = mean_alpha(img);
    let leaf = r.db().layout().leaf_level();
    eprintln!(
        "colin27 64×48, brick 32, f32, step 0.125: RMSE {e:.2e}, max {mx:.2e}, mean alpha {ma:.3} \
         (reference {:.3}); cut {} nodes, {} leaves with data, adequate {}, leaf level {leaf}; \
         converge {gpu_s:.1} s, reference {ref_s:.1} s",
        want.iter().map(|p| p[3]).sum::<f64>() / want.len() as f64,
        f.stats.cut_nodes,
        f.stats.cut_leaves_with_data,
        f.stats.adequate
    );
    assert_valid("colin27", img);
    assert!(f.stats.adequate);
    assert!(ma > 0.05, "the image is empty: mean alpha {ma}");
    assert!(e <= 1e-3, "RMSE {e} against the reference integral");
}

/// Error against the exact integral for coarser and coarser settings of one
/// dataset: longer steps, 8-bit bricks, interpolation by the texture unit.
#[test]
fn coarser_settings_have_larger_error() {
    let n = 64;
    let vol = marschner_lobb(n);
    let dir = tempfile::tempdir().unwrap();
    let tf = translucent();
    let placement = centred(0.3);
    let view = View::window([48, 40], [0.4, 0.33], [0.02, 0.01, 0.8]);
    let want = reference_image(&vol, &tf, &placement, &view, 1e-7);
    let f32_filterable = parallax_backend::gpu::Gpu::new()
        .unwrap()
        .device
        .features()
        .contains(wgpu::Features::FLOAT32_FILTERABLE);
    let mut errors = Vec::new();
    for enc in [BrickEncoding::F32, BrickEncoding::U8Range] {
        let db = dir.path().join(format!("ml-{}.pxo", enc.name()));
        import_volume(&vol, &db, 16, enc);
        for interpolation in [Interpolation::Exact, Interpolation::Hardware] {
            let base = RenderConfig {
                interpolation,
                ..exact_config()
            };
            let mut r = renderer(&db, &tf, &base);
            let steps: &[f64] = match (enc, interpolation) {
                (BrickEncoding::F32, Interpolation::Exact) => &[0.125, 0.5, 2.0],
                _ => &[0.125],
            };
            for &step in steps {
                let cfg = RenderConfig {
                    step_factor: exact_at(step).step_factor,
                    ..base.clone()
                };
                let f = r.converge(&placement, &[view], &cfg, 20).unwrap();
                assert!(f.stats.adequate);
                assert_valid("marschner-lobb", &f.images[0]);
                let (e, mx) = diff_ref(&f.images[0], &want);
                eprintln!(
                    "marschner-lobb 64³ brick 16, {} bricks, {interpolation:?} filtering{}, \
                     step {step}: RMSE {e:.3e}, max {mx:.3e}, mean alpha {:.3}",
                    enc.name(),
                    if interpolation == Interpolation::Hardware
                        && enc == BrickEncoding::F32
                        && !f32_filterable
                    {
                        " (not filterable here: falls back to exact)"
                    } else {
                        ""
                    },
                    mean_alpha(&f.images[0])
                );
                errors.push((enc, interpolation, step, e));
            }
        }
    }
    let e = |enc, interp, step| {
        errors
            .iter()
            .find(|x| x.0 == enc && x.1 == interp && x.2 == step)
            .unwrap()
            .3
    };
    use BrickEncoding::{U8Range, F32};
    use Interpolation::{Exact, Hardware};
    let by_step = [e(F32, Exact, 0.125), e(F32, Exact, 0.5), e(F32, Exact, 2.0)];
    assert!(
        by_step[0] < by_step[1] && by_step[1] < by_step[2],
        "error must grow with the step: {by_step:?}"
    );
    // The finest setting is the project's bar against the exact integral.
    assert!(by_step[0] <= 1e-3);
    // 8-bit data at full detail: the 8-bit bricks are on the unit grid,
    // lossless, so their error is the full bricks' (to f32 rounding).
    let (u8e, fe) = (e(U8Range, Exact, 0.125), e(F32, Exact, 0.125));
    assert!(
        (u8e - fe).abs() <= 1e-3 * fe,
        "8-bit bricks {u8e} vs full {fe}"
    );
    // 8-bit sub-texel weights on top of 8-bit bricks.
    let u8hw = e(U8Range, Hardware, 0.125);
    assert!(u8hw >= u8e, "hardware {u8hw} vs exact {u8e}");
    assert!(u8hw <= 1e-3 && e(F32, Hardware, 0.125) <= 1e-3);
}

/// The bricks a lone view's cut reads, found with the loader alone under the
/// renderer's budgets and emptiness test.
fn loader_bricks(
    db: &Path,
    tf: &TransferFunction,
    view: View,
    placement: &Placement,
) -> HashSet<NodeKey> {
    let db = std::sync::Arc::new(OctreeDb::open(db).unwrap());
    let cfg = exact_config();
    let (lo, hi) = (db.summary.value_min as f64, db.summary.value_max as f64);
    let empty = EmptinessTable::new(tf, lo, hi, PreintTable::suggested_bins(lo, hi, true)).unwrap();
    let is_empty = |a: f32, b: f32| empty.is_empty(a as f64, b as f64);
    let side = db.layout().stored_side() as u32;
    let float = db.encoding() != BrickEncoding::U8Range;
    let mut loader = Loader::new(
        db.clone(),
        LoaderConfig {
            cpu_budget_bytes: (cfg.cpu_cache_mb * (1 << 20) as f64) as u64,
            gpu_slots: BrickPool::slots_for_budget(
                (cfg.gpu_cache_mb * (1 << 20) as f64) as u64,
                side,
                float,
            )
            .min(MAX_INDEX_NODES as u32),
            upload_budget: cfg.upload_budget,
            accuracy: cfg.accuracy,
            opaque_detail: 1.0,
            use_feedback: false,
            frustum_culling: true,
            io_threads: 2,
        },
    );
    let mut keys = HashSet::new();
    for _ in 0..30 {
        let f = loader.update(&[view], placement, &is_empty, None);
        keys.extend(f.uploads.iter().map(|u| u.key));
        if f.stats.adequate && f.uploads.is_empty() && f.requests.is_empty() {
            return keys;
        }
        loader.wait_idle();
    }
    panic!("the loader did not converge");
}

#[test]
fn views_share_the_cache() {
    let vol = marschner_lobb(64);
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("ml.pxo");
    // Bricks of 8 (585 nodes): fine enough for the frustum to cut whole
    // subtrees of one view and not of another.
    import_volume(&vol, &db, 8, BrickEncoding::U8Range);
    let tf = translucent();
    let cfg = exact_config();
    let placement = centred(0.3);
    // A small screen at the volume's centre seen from three eyes: the three
    // view pyramids cross in the middle of the volume and part in front of
    // and behind it, so the cuts overlap without being equal.
    let views: Vec<View> = [[-0.2, 0.0, 0.5], [0.0, 0.05, 0.5], [0.2, -0.03, 0.45]]
        .iter()
        .map(|&eye| View::window([40, 30], [0.08, 0.06], eye))
        .collect();

    let mut shared = renderer(&db, &tf, &cfg);
    let (sf, s_frames, s_uploads) = converge_counting(&mut shared, &placement, &views, &cfg, 30);
    let mut alone_bytes = Vec::new();
    let mut alone_sets = Vec::new();
    let mut union = HashSet::new();
    for (i, v) in views.iter().enumerate() {
        let mut r = renderer(&db, &tf, &cfg);
        let (f, frames, uploads) = converge_counting(&mut r, &placement, &[*v], &cfg, 30);
        let (e, mx) = diff(&sf.images[i], &f.images[0]);
        let bitwise = sf.images[i] == f.images[0];
        let keys = loader_bricks(&db, &tf, *v, &placement);
        eprintln!(
            "view {i} alone: {frames} frames, {uploads} uploads, {} resident, {} bytes read \
             ({} bricks by the loader alone, {} bytes); shared vs alone image: RMSE {e:.1e}, \
             max {mx:.1e}, bitwise identical {bitwise}; mean alpha {:.3}",
            f.stats.resident,
            f.stats.bytes_read,
            keys.len(),
            stored_bytes(shared.db(), &keys),
            mean_alpha(&f.images[0])
        );
        assert_valid("alone", &f.images[0]);
        assert_valid("shared", &sf.images[i]);
        assert!(mean_alpha(&f.images[0]) > 0.05);
        assert!(
            mx <= 1e-6,
            "view {i}: shared and alone images differ by {mx}"
        );
        // the loader-only replay reads what the renderer read
        assert_eq!(f.stats.bytes_read, stored_bytes(shared.db(), &keys));
        assert_eq!(uploads as usize, keys.len());
        alone_bytes.push(f.stats.bytes_read);
        union.extend(keys.iter().copied());
        alone_sets.push(keys);
    }
    let sum: u64 = alone_bytes.iter().sum();
    let union_bytes = stored_bytes(shared.db(), &union);
    let overlap = alone_sets[0].intersection(&alone_sets[1]).count()
        + alone_sets[1].intersection(&alone_sets[2]).count()
        + alone_sets[0].intersection(&alone_sets[2]).count();
    eprintln!(
        "shared: {s_frames} frames, {s_uploads} uploads, {} resident, {} bytes read; union of the \
         lone cuts {} bricks = {union_bytes} bytes; sum of lone runs {sum} bytes ({} bricks); \
         pairwise overlap {overlap} bricks",
        sf.stats.resident,
        sf.stats.bytes_read,
        union.len(),
        alone_sets.iter().map(|s| s.len()).sum::<usize>()
    );
    assert_eq!(sf.stats.bytes_read, union_bytes, "each brick read once");
    assert_eq!(s_uploads as usize, union.len(), "each brick uploaded once");
    assert_eq!(sf.stats.resident as usize, union.len());
    assert!(overlap > 0);
    assert!(sf.stats.bytes_read < sum);
    assert!(sf.stats.bytes_read > *alone_bytes.iter().max().unwrap());

    // Interpolated by the texture unit, a sample depends on where its brick
    // sits in the pool (texel coordinates are normalised over the whole
    // pool; lavapipe's sub-texel weights have 8 bits), and the shared and
    // lone runs place bricks in different slots: the same cut, images equal
    // only to within that rounding (measured: max 2.7e-5).
    let hw = RenderConfig {
        interpolation: Interpolation::Hardware,
        ..cfg.clone()
    };
    let mut shared = renderer(&db, &tf, &hw);
    let (shf, _, _) = converge_counting(&mut shared, &placement, &views, &hw, 30);
    assert_eq!(shf.stats.bytes_read, union_bytes);
    for (i, v) in views.iter().enumerate() {
        let mut r = renderer(&db, &tf, &hw);
        let (f, _, _) = converge_counting(&mut r, &placement, &[*v], &hw, 30);
        let (e, mx) = diff(&shf.images[i], &f.images[0]);
        eprintln!(
            "hardware filtering, view {i}: shared vs alone RMSE {e:.1e}, max {mx:.1e}, bitwise \
             identical {}",
            shf.images[i] == f.images[0]
        );
        assert_valid("hardware", &f.images[0]);
        assert!(mx <= 1e-4, "view {i}: {mx}");
    }
}

/// G10 §5 reports visibility feedback cutting the working set of an opaque
/// scene from 4553 to 1554 bricks (−66%). Here: Colin27 with an opaque skin,
/// seen from the front, refined to full resolution (accuracy 0.5 already
/// gives the same cut as anything finer with bricks of 16), with and without
/// feedback. Measured: 1376 → 686 leaves with data (−50%). Coarser cuts gain
/// less: bricks of 16 at accuracy 1.0, 212 → 172 (−19%); bricks of 32 at
/// accuracy 0.5, 212 → 172 (−19%), at accuracy 1.0, 35 → 35 — with few,
/// large bricks almost every brick holds some visible skin.
#[test]
fn visibility_feedback_shrinks_the_opaque_cut() {
    let path = Path::new(COLIN27);
    if !path.exists() {
        eprintln!("SKIPPED: {COLIN27} is not installed (apt: mricron-data)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("colin27-u8.pxo");
    store::import(
        data::open(path, None).unwrap().as_mut(),
        &db,
        COLIN27,
        &ImportOptions {
            brick: 16,
            encoding: BrickEncoding::U8Range,
            ..Default::default()
        },
    )
    .unwrap();
    let tf = TransferFunction::load(configs().join("tf/colin27-skin.toml")).unwrap();
    let placement = colin_placement();
    let view = View::window([128, 96], [0.4, 0.3], [0.0, 0.0, 0.8]);
    let mut out = Vec::new();
    for interpolation in [Interpolation::Exact, Interpolation::Hardware] {
        for feedback in [false, true] {
            let cfg = RenderConfig {
                shading: Shading::None,
                accuracy: 0.5,
                early_termination: 0.99,
                visibility_feedback: feedback,
                interpolation,
                ..RenderConfig::default()
            };
            let mut r = renderer(&db, &tf, &cfg);
            let t = Instant::now();
            let (f, frames, uploads) = converge_counting(&mut r, &placement, &[view], &cfg, 60);
            eprintln!(
                "colin27 skin, brick 16 u8, 128×96, accuracy 0.5, {interpolation:?} filtering, \
                 feedback {feedback}: {frames} frames ({:.1} s), cut {} nodes, {} leaves with \
                 data, {} resident, {uploads} uploads, {} bytes read, {} visible, mean alpha {:.3}",
                t.elapsed().as_secs_f64(),
                f.stats.cut_nodes,
                f.stats.cut_leaves_with_data,
                f.stats.resident,
                f.stats.bytes_read,
                f.stats.visible,
                mean_alpha(&f.images[0])
            );
            assert_valid("skin", &f.images[0]);
            assert!(f.stats.adequate);
            assert!(mean_alpha(&f.images[0]) > 0.2, "the head fills the view");
            out.push(f);
        }
    }
    for (name, off, on) in [("exact", &out[0], &out[1]), ("hardware", &out[2], &out[3])] {
        let (e, mx) = diff(&on.images[0], &off.images[0]);
        let (a, b) = (
            off.stats.cut_leaves_with_data,
            on.stats.cut_leaves_with_data,
        );
        let shrink = 1.0 - b as f64 / a as f64;
        eprintln!(
            "{name} filtering, feedback off → on: leaves with data {a} → {b} ({:.0}% fewer), \
             resident {} → {}, bytes read {} → {}; image difference RMSE {e:.2e}, max {mx:.2e}",
            100.0 * shrink,
            off.stats.resident,
            on.stats.resident,
            off.stats.bytes_read,
            on.stats.bytes_read
        );
        assert!(
            shrink >= 0.40,
            "{name}: only {:.1}% fewer leaves with data",
            100.0 * shrink
        );
        assert!(on.stats.resident < off.stats.resident);
        assert!(on.stats.bytes_read < off.stats.bytes_read);
        if name == "exact" {
            // Every node a ray traverses is visible and refined as without
            // feedback; exact filtering does not depend on which slot a
            // brick sits in: the images are the same (measured: bit for bit).
            assert!(mx <= 1e-6, "{name}: max difference {mx}");
        } else {
            // The texture unit's weights depend on the slot a brick sits in
            // (texel coordinates normalised over the whole pool, 8-bit
            // sub-texel weights on lavapipe), and the two runs place bricks
            // differently. A ray whose opacity crosses the 0.99 early
            // termination one step earlier or later then differs by up to
            // the last 1% it would have gathered: max ≤ 0.01 per channel.
            // Measured: RMSE 4.4e-5, max 5.2e-3.
            assert!(mx <= 1e-2 + 1e-4, "{name}: max difference {mx}");
            assert!(e <= 5e-4, "{name}: RMSE {e}");
        }
    }
}

/// A volume far larger than both caches: 256³ Marschner–Lobb in bricks of 16
/// (4681 bricks, 150 MB decoded), rendered close up with a 4 MiB CPU cache
/// and a 2 MiB GPU pool (262 slots), while the view's full-detail cut needs
/// more than three times as many slots.
///
/// What "converges" means here: the budget cannot hold the full-detail cut,
/// so the image cannot reach the full-detail image. The renderer refines
/// largest projected voxels first until the pool is full and then stops
/// changing; its image approaches the best the budget allows. Measured as:
/// the error against the full-detail image (same view, big budgets) falls
/// frame by frame, the last frames are identical (nothing more uploaded or
/// read), the pool is full, and the final image is at least as good as a
/// uniformly coarser rendering whose cut does fit the budget.
#[test]
fn out_of_core_volume_converges_within_budget() {
    let dir = tempfile::tempdir().unwrap();
    let n = 256;
    let nrrd = dir.path().join("ml256.nrrd");
    let t = Instant::now();
    write_synth(SynthKind::MarschnerLobb, n, VoxelType::U8, &nrrd, |_| {}).unwrap();
    let db = dir.path().join("ml256.pxo");
    store::import(
        data::open(&nrrd, None).unwrap().as_mut(),
        &db,
        "ml256",
        &ImportOptions {
            brick: 16,
            encoding: BrickEncoding::U8Range,
            ..Default::default()
        },
    )
    .unwrap();
    let odb = OctreeDb::open(&db).unwrap();
    let layout = *odb.layout();
    let stored = odb.nodes.iter().filter(|r| r.is_stored()).count() as u64;
    let decoded = stored * layout.stored_len() as u64 * 4;
    let slot = BrickPool::slot_bytes(layout.stored_side() as u32, false);
    let mib = (1u64 << 20) as f64;
    let cfg = RenderConfig {
        shading: Shading::None,
        accuracy: 0.5,
        step_factor: 0.5,
        early_termination: 0.99,
        cpu_cache_mb: 4.0,
        gpu_cache_mb: 2.0,
        visibility_feedback: false,
        // Every node to the same accuracy (the function's value 255 can
        // stop a ray within a level-2 voxel), so that 1.5 below is a
        // uniformly coarser cut.
        opaque_detail: 1.0,
        ..RenderConfig::default()
    };
    let (cpu_budget, gpu_budget) = (
        (cfg.cpu_cache_mb * mib) as u64,
        (cfg.gpu_cache_mb * mib) as u64,
    );
    let slots = gpu_budget / slot;
    let (cpu_ratio, gpu_ratio) = (
        decoded as f64 / cpu_budget as f64,
        decoded as f64 / gpu_budget as f64,
    );
    eprintln!(
        "256³ u8, brick 16: {} nodes, {stored} stored, {:.0} MB decoded (f32), {:.0} MB as 8-bit \
         slots; budgets: CPU {} MiB ({cpu_ratio:.0}× smaller than the decoded bricks), GPU {} MiB \
         ({gpu_ratio:.0}× smaller; {slots} slots); prepared in {:.1} s",
        odb.nodes.len(),
        decoded as f64 / 1e6,
        (stored * slot) as f64 / 1e6,
        cfg.cpu_cache_mb,
        cfg.gpu_cache_mb,
        t.elapsed().as_secs_f64()
    );
    assert!(cpu_ratio >= 8.0 && gpu_ratio >= 8.0);

    let tf = translucent();
    let placement = centred(0.3);
    // Close up: the eye 27 cm from the screen, 12 cm from the volume's
    // centre.
    let view = View::window([48, 48], [0.3, 0.3], [0.02, 0.01, 0.27]);

    // Full detail, and a uniformly coarser cut that fits the budget.
    let mut refs = Vec::new();
    for accuracy in [cfg.accuracy, 1.5] {
        let big = RenderConfig {
            cpu_cache_mb: 1024.0,
            gpu_cache_mb: 512.0,
            accuracy,
            ..cfg.clone()
        };
        let mut r = renderer(&db, &tf, &big);
        let (f, frames, _) = converge_counting(&mut r, &placement, &[view], &big, 40);
        eprintln!(
            "big budgets, accuracy {accuracy}: {frames} frames, cut {} nodes, {} leaves with data, \
             {} resident = {:.2} MiB of slots ({:.1}× the small pool), {:.1} MiB CPU cache",
            f.stats.cut_nodes,
            f.stats.cut_leaves_with_data,
            f.stats.resident,
            (f.stats.resident * slot) as f64 / mib,
            f.stats.resident as f64 / slots as f64,
            f.stats.cpu_bytes as f64 / mib
        );
        assert!(f.stats.adequate);
        assert_valid("big budgets", &f.images[0]);
        refs.push(f);
    }
    let best = &refs[0].images[0];
    assert!(mean_alpha(best) > 0.05);
    assert!(
        refs[0].stats.resident > 3 * slots,
        "the full-detail cut must be far larger than the small GPU budget"
    );
    assert!(refs[1].stats.resident <= slots, "the coarser cut fits");
    let (fit_err, _) = diff(&refs[1].images[0], best);
    eprintln!("accuracy 1.5 (fits the budget) vs full detail: RMSE {fit_err:.3e}");

    let mut r = renderer(&db, &tf, &cfg);
    r.sync_io = true;
    let frames = 24usize;
    let mut errors = Vec::new();
    let mut images = Vec::new();
    let mut last_stats = None;
    let t = Instant::now();
    for i in 0..frames {
        let f = r.frame(i as u64, &placement, &[view], &cfg).unwrap();
        let s = &f.stats;
        assert!(
            s.resident * slot <= gpu_budget,
            "frame {i}: {} slots resident",
            s.resident
        );
        assert!(
            s.cpu_bytes <= cpu_budget,
            "frame {i}: CPU cache {} bytes",
            s.cpu_bytes
        );
        assert_valid("budgeted", &f.images[0]);
        let (e, mx) = diff(&f.images[0], best);
        eprintln!(
            "frame {i:2}: RMSE vs full detail {e:.3e} (max {mx:.2e}); cut {} nodes, {} leaves \
             with data, {} resident ({:.2} MiB), {} uploaded, {} requested, CPU cache {:.2} MiB, \
             {} bytes read, adequate {}",
            s.cut_nodes,
            s.cut_leaves_with_data,
            s.resident,
            (s.resident * slot) as f64 / mib,
            s.uploaded,
            s.requested,
            s.cpu_bytes as f64 / mib,
            s.bytes_read,
            s.adequate
        );
        errors.push(e);
        images.push(f.images[0].clone());
        last_stats = Some(f.stats);
    }
    let s = last_stats.unwrap();
    let (first, mid, last) = (errors[1], errors[frames / 2], errors[frames - 1]);
    eprintln!(
        "{frames} budgeted frames in {:.1} s; RMSE vs full detail: frame 1 (first image) \
         {first:.3e}, frame {} {mid:.3e}, frame {} {last:.3e}; coarser cut that fits \
         {fit_err:.3e}; pool {} of {slots} slots",
        t.elapsed().as_secs_f64(),
        frames / 2,
        frames - 1,
        s.resident
    );
    // Frame 0 has no image yet (the root is being read: never block).
    for w in errors[1..].windows(2) {
        assert!(w[1] <= w[0] + 1e-6, "the error rose: {errors:?}");
    }
    assert!(mid <= first && last <= mid);
    assert!(last < 0.5 * first, "{first} → {last}");
    // Settled: nothing more to upload or read, the same image, a full pool.
    assert_eq!(s.uploaded, 0);
    assert_eq!(s.requested, 0);
    assert!(!s.adequate, "the budget cannot hold an adequate cut");
    assert!(images[frames - 8..]
        .iter()
        .all(|im| *im == images[frames - 1]));
    assert!(s.resident + 8 > slots, "the pool is full");
    // At least as good as the best uniform-accuracy cut that fits.
    assert!(last <= fit_err, "{last} vs {fit_err}");
    // Measured: 2.0e-2 (frame 1: 4.6e-2). Not below 1e-2: what is missing
    // is the full-detail refinement of the bricks nearest the eye, which
    // needs 6× the pool; the accuracy-1.5 cut that fits is 2.1e-2 off.
    assert!(last < 2.5e-2, "last frame RMSE {last}");
}

/// Path length (data units) of each pixel's ray inside the volume's box.
fn path_lengths(vol: &Volume, placement: &Placement, view: &View) -> Vec<f64> {
    let ext = vol.info.extent();
    let [w, h] = view.resolution;
    (0..w * h)
        .map(|p| {
            let (o, d) = view.ray(p % w, p / w);
            let (vo, vd) = placement.ray_to_volume(ext, o, d);
            reference::clip_to_box(vo, vd, glam::DVec3::from(ext)).map_or(0.0, |(a, b)| b - a)
        })
        .collect()
}

#[test]
fn stress_cases_render_or_fail_clearly() {
    let n = 32;
    let vol = marschner_lobb(n);
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("ml32.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    let odb = OctreeDb::open(&db).unwrap();
    let root_len = odb.node(NodeKey::root()).unwrap().len as u64;
    let tf = translucent();
    let cfg = exact_config();
    let placement = centred(0.3);
    let normal = View::window([40, 30], [0.4, 0.3], [0.02, 0.01, 0.8]);

    // 1. A zero-size view, alone and beside a normal one.
    let zero = View {
        resolution: [0, 0],
        ..normal
    };
    let mut r = renderer(&db, &tf, &cfg);
    match r.converge(&placement, &[zero], &cfg, 20) {
        Ok(f) => {
            eprintln!(
                "zero-size view: empty image ({} pixels), cut {} nodes",
                f.images[0].len(),
                f.stats.cut_nodes
            );
            assert!(f.images[0].is_empty());
        }
        Err(e) => {
            eprintln!("zero-size view: error {e:#}");
            assert!(!format!("{e:#}").is_empty());
        }
    }
    let mut r = renderer(&db, &tf, &cfg);
    let alone = r.converge(&placement, &[normal], &cfg, 20).unwrap();
    let mut r = renderer(&db, &tf, &cfg);
    let both = r.converge(&placement, &[zero, normal], &cfg, 20).unwrap();
    assert!(both.images[0].is_empty());
    assert_eq!(both.images[1], alone.images[0]);
    let want = reference_image(&vol, &tf, &placement, &normal, 1e-7);
    let (e, _) = diff_ref(&alone.images[0], &want);
    eprintln!("normal view beside a zero-size one: identical to alone; RMSE vs reference {e:.2e}");
    assert!(e <= 1e-3);

    // 2. The eye at the centre of the volume.
    let inside_pl = Placement {
        center: [0.0, 0.0, 0.5],
        ..placement
    };
    let inside = View::window([40, 30], [0.4, 0.3], [0.0, 0.0, 0.5]);
    let mut r = renderer(&db, &tf, &cfg);
    let f = r.converge(&inside_pl, &[inside], &cfg, 20).unwrap();
    let want = reference_image(&vol, &tf, &inside_pl, &inside, 1e-7);
    let (e, mx) = diff_ref(&f.images[0], &want);
    eprintln!(
        "eye inside the volume: RMSE vs reference {e:.2e}, max {mx:.2e}, mean alpha {:.3}, \
         cut {} nodes, {} leaves with data",
        mean_alpha(&f.images[0]),
        f.stats.cut_nodes,
        f.stats.cut_leaves_with_data
    );
    assert_valid("inside", &f.images[0]);
    assert!(mean_alpha(&f.images[0]) > 0.05);
    assert!(e <= 1e-3);

    // 3. Looking away: the volume is behind the eye.
    let behind = Placement {
        center: [0.0, 0.0, 2.0],
        ..placement
    };
    let mut r = renderer(&db, &tf, &cfg);
    let f = r.converge(&behind, &[normal], &cfg, 20).unwrap();
    eprintln!(
        "looking away: max value {:.1e}, cut {} nodes, {} bytes read (root brick {root_len})",
        f.images[0].iter().flatten().fold(0f32, |a, &b| a.max(b)),
        f.stats.cut_nodes,
        f.stats.bytes_read
    );
    assert!(f.images[0].iter().flatten().all(|&v| v == 0.0));
    assert_eq!(f.stats.cut_nodes, 1);
    assert_eq!(f.stats.bytes_read, root_len);

    // 4. A transfer function transparent everywhere.
    let clear = TransferFunction::from_points(vec![ControlPoint::new(0.0, [1.0; 3], 0.0)]).unwrap();
    let mut r = renderer(&db, &clear, &cfg);
    let f = r.converge(&placement, &[normal], &cfg, 20).unwrap();
    eprintln!(
        "transparent TF: max value {:.1e}, cut {} nodes, {} bytes read",
        f.images[0].iter().flatten().fold(0f32, |a, &b| a.max(b)),
        f.stats.cut_nodes,
        f.stats.bytes_read
    );
    assert!(f.images[0].iter().flatten().all(|&v| v == 0.0));
    assert!(f.stats.bytes_read <= root_len);

    // 5. A transfer function opaque everywhere (τ = 40 per voxel): opacity
    // 1 − exp(−40·L) along a path of length L, the colour times it.
    let color = [0.8, 0.6, 0.4];
    let tau = 40.0;
    let opaque = TransferFunction::from_points(vec![ControlPoint::new(0.0, color, tau)]).unwrap();
    let ocfg = RenderConfig {
        early_termination: 0.99,
        ..cfg.clone()
    };
    let mut r = renderer(&db, &opaque, &ocfg);
    let f = r.converge(&placement, &[normal], &ocfg, 20).unwrap();
    assert_valid("opaque", &f.images[0]);
    let lens = path_lengths(&vol, &placement, &normal);
    let (mut worst_a, mut worst_c, mut hit, mut min_deep) = (0f64, 0f64, 0, 1f64);
    for (p, &l) in f.images[0].iter().zip(&lens) {
        let a = p[3] as f64;
        let want = 1.0 - (-tau * l).exp();
        // early termination stops at 0.99, so anything in [0.99, want]
        let lo = want.min(0.99);
        let err = if a < lo { lo - a } else { (a - want).max(0.0) };
        worst_a = worst_a.max(err);
        for c in 0..3 {
            worst_c = worst_c.max((p[c] as f64 - color[c] * a).abs());
        }
        if l > 0.2 {
            hit += 1;
            min_deep = min_deep.min(a);
        }
    }
    eprintln!(
        "opaque TF: {hit} pixels with a path > 0.2 voxel, least opacity there {min_deep:.5}; \
         worst opacity error {worst_a:.1e}, worst colour − c·α {worst_c:.1e}"
    );
    assert!(hit > 100);
    assert!(min_deep >= 0.99);
    assert!(worst_a <= 1e-3 && worst_c <= 1e-3);

    // 6. A volume one voxel thick.
    let slab = Volume::from_fn([64, 64, 1], [1.0; 3], VoxelType::U8, |i, j, _| {
        (synth_value(SynthKind::MarschnerLobb, i, j, 40, 64) * 255.0).round() as f32
    });
    let sdb = dir.path().join("slab.pxo");
    import_volume(&slab, &sdb, 16, BrickEncoding::F32);
    let thick = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.2, 0.2, 0.2], 0.05),
        ControlPoint::new(128.0, [0.9, 0.6, 0.3], 0.8),
        ControlPoint::new(255.0, [0.3, 0.6, 1.0], 2.0),
    ])
    .unwrap();
    let slab_pl = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [30.0, 20.0, 0.0],
        size: 0.3,
    };
    let mut r = renderer(&sdb, &thick, &cfg);
    let f = r.converge(&slab_pl, &[normal], &cfg, 20).unwrap();
    let want = reference_image(&slab, &thick, &slab_pl, &normal, 1e-7);
    let (e, mx) = diff_ref(&f.images[0], &want);
    eprintln!(
        "64×64×1 slab: RMSE vs reference {e:.2e}, max {mx:.2e}, mean alpha {:.3}, cut {} nodes",
        mean_alpha(&f.images[0]),
        f.stats.cut_nodes
    );
    assert_valid("slab", &f.images[0]);
    assert!(mean_alpha(&f.images[0]) > 0.05);
    assert!(e <= 1e-3);

    // 7. Budgets too small for the root brick.
    for (field, small) in [
        (
            "render.gpu_cache_mb",
            RenderConfig {
                gpu_cache_mb: 1e-4,
                ..cfg.clone()
            },
        ),
        (
            "render.cpu_cache_mb",
            RenderConfig {
                cpu_cache_mb: 1e-4,
                ..cfg.clone()
            },
        ),
    ] {
        match Renderer::new(&db, &small) {
            Ok(_) => panic!("{field} = 1e-4 MiB accepted"),
            Err(e) => {
                let msg = format!("{e:#}");
                eprintln!("tiny budget: {msg}");
                assert!(msg.contains(field), "{msg}");
            }
        }
    }

    // 8. Budgets that hold the root but not one set of its children cannot
    //    refine: refused, naming the smallest budget that works, which is
    //    then accepted and refines.
    let brick_mib = (odb.layout().stored_len() * 4) as f64 / (1 << 20) as f64;
    for (field, small) in [
        (
            "render.gpu_cache_mb",
            RenderConfig {
                gpu_cache_mb: 8.5 * brick_mib,
                ..cfg.clone()
            },
        ),
        (
            "render.cpu_cache_mb",
            RenderConfig {
                cpu_cache_mb: 7.5 * brick_mib,
                ..cfg.clone()
            },
        ),
    ] {
        let msg = match Renderer::new(&db, &small) {
            Ok(_) => panic!("{field} below one sibling set accepted"),
            Err(e) => format!("{e:#}"),
        };
        eprintln!("small budget: {msg}");
        assert!(
            msg.contains(field) && msg.contains("smallest that works"),
            "{msg}"
        );
        let smallest: f64 = msg.rsplit(' ').next().unwrap().parse().unwrap();
        let mut ok = small.clone();
        if field.contains("gpu") {
            ok.gpu_cache_mb = smallest;
        } else {
            ok.cpu_cache_mb = smallest;
        }
        let mut r = renderer(&db, &tf, &ok);
        let f = r.converge(&placement, &[normal], &ok, 40).unwrap();
        assert!(f.stats.cut_nodes > 1, "{field} = {smallest}: refines");
    }
}

/// Frustum culling for light field views (η > 0): the volume swept by a
/// multi-centre projector's rays. A view of part of the screen culls the
/// bricks beside it, and the image equals the unculled one bit for bit.
#[test]
fn light_field_frustum_culling_removes_nothing_that_contributes() {
    let vol = marschner_lobb(64);
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("ml.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::U8Range);
    let cfg = RenderConfig {
        accuracy: 0.5,
        visibility_feedback: false,
        ..exact_config()
    };
    let placement = centred(0.3);
    for (eta, eye_x) in [(1.0, 0.15), (0.5, -0.2), (1.0, -0.35)] {
        // The left third of a 0.6 m screen, from a projector off to the side.
        let view = View {
            resolution: [48, 72],
            region: [-0.3, -0.15, 0.2, 0.3],
            eye: [eye_x, 0.0, 0.9],
            observer: [0.0, 0.0, 0.8],
            eta,
        };
        let mut images = Vec::new();
        let mut leaves = Vec::new();
        for culling in [true, false] {
            let mut r = renderer(&db, &translucent(), &cfg);
            r.set_frustum_culling(culling);
            let f = r.converge(&placement, &[view], &cfg, 40).unwrap();
            assert!(f.stats.adequate);
            images.push(f.images[0].clone());
            leaves.push(f.stats.cut_leaves_with_data);
        }
        eprintln!(
            "η {eta}, projector x {eye_x}: {} leaves with data culled, {} without",
            leaves[0], leaves[1]
        );
        assert!(leaves[0] < leaves[1], "culling removed nothing: {leaves:?}");
        assert!(mean_alpha(&images[0]) > 0.02, "the view sees the volume");
        assert!(images[0] == images[1], "η {eta}: culling changed the image");
    }
}
