//! The GPU ray caster on a full-detail cut against the reference integral.

mod support;
use parallax_backend::data::synth::{synth_value, SynthKind};
use parallax_backend::gpu::Gpu;
use parallax_backend::index::{CutNode, SpatialIndex};
use parallax_backend::raycast::{
    BrickPool, Filtering, Raycaster, RenderInputs, RenderSettings, SceneGeometry, TfTable,
};
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::store::{self, ImportOptions};
use parallax_backend::store::{BrickEncoding, OctreeDb};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::Preintegration;
use parallax_common::tf::{ControlPoint, PreintTable, TransferFunction};
use std::collections::HashMap;

fn tf() -> TransferFunction {
    support::translucent()
}

struct Setup {
    vol: Volume,
    db: OctreeDb,
    _dir: tempfile::TempDir,
}

fn setup(kind: SynthKind, n: usize, encoding: BrickEncoding) -> Setup {
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        (synth_value(kind, i, j, k, n) * 255.0).round() as f32
    });
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &path,
        "v",
        &ImportOptions {
            brick: 16,
            encoding,
            ..Default::default()
        },
    )
    .unwrap();
    let db = OctreeDb::open(&path).unwrap();
    Setup { vol, db, _dir: dir }
}

/// Every node refined down to the source level, every stored brick in a slot.
fn full_cut(
    gpu: &Gpu,
    db: &OctreeDb,
    float: bool,
) -> (
    HashMap<parallax_backend::store::NodeKey, CutNode>,
    BrickPool,
) {
    let l = *db.layout();
    let mut pool =
        BrickPool::new(gpu, db.nodes.len() as u32, l.stored_side() as u32, float).unwrap();
    let mut cut = HashMap::new();
    for (slot, n) in db.nodes.iter().enumerate() {
        let data = db.read_brick(n.key).unwrap();
        if let Some(d) = &data {
            pool.upload(gpu, slot as u32, d, None, 0.0);
        }
        cut.insert(
            n.key,
            CutNode {
                refined: (n.key.level as u32) < l.leaf_level(),
                slot: data.map(|_| slot as u32),
                min: n.min,
                max: n.max,
            },
        );
    }
    (cut, pool)
}

fn scene(db: &OctreeDb) -> SceneGeometry {
    SceneGeometry::new(
        Placement {
            center: [0.0, 0.0, 0.0],
            rotation_deg: [20.0, 35.0, 0.0],
            size: 0.3,
        },
        *db.layout(),
        db.header.info.spacing,
    )
}

/// A full-detail render of the standard test view against the reference
/// integral (step 1/8 voxel, no early termination, no shading).
struct Measured {
    image: Vec<[f32; 4]>,
    reference: Vec<[f64; 4]>,
    rmse: f64,
    max: f64,
    mean_alpha: f64,
    running_integral: bool,
    end_path: bool,
    closed_form: bool,
    feedback: Vec<u32>,
}

/// How the ray caster looks up a segment's optics.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Path {
    /// From the segment's ends, where the table allows (the default).
    End,
    /// Per segment from the 1D table.
    Segment,
    /// The 2D table, bilinearly (`preintegration = "2d"`).
    Grid,
    /// In closed form (`preintegration = "analytic"`).
    Analytic,
}

fn measure(
    gpu: &Gpu,
    rc: &mut Raycaster,
    s: &Setup,
    f: &TransferFunction,
    cut: &HashMap<parallax_backend::store::NodeKey, CutNode>,
    pool: &BrickPool,
    path: Path,
) -> Measured {
    let range = (s.db.summary.value_min, s.db.summary.value_max);
    let (lo, hi) = (range.0 as f64, range.1 as f64);
    let table = PreintTable::new(f, lo, hi, PreintTable::suggested_bins(lo, hi, true)).unwrap();
    let mut gtf = TfTable::new(gpu, &table, f);
    gtf.allow_end_path(path == Path::End);
    if path == Path::Grid {
        gtf.build_grid(gpu, &table);
    }
    let index = SpatialIndex::build(s.db.layout(), cut, range).unwrap();
    let sc = scene(&s.db);
    let view = View::window([40, 32], [0.4, 0.32], [0.02, 0.01, 0.8]);
    let settings = RenderSettings {
        step_factor: 0.125,
        early_termination: 1.0,
        shading: false,
        preintegration: match path {
            Path::Grid => Preintegration::TwoD,
            Path::Analytic => Preintegration::Analytic,
            _ => Preintegration::Exact,
        },
        ..Default::default()
    };
    let mut out = rc
        .render(
            gpu,
            &RenderInputs {
                pool,
                index: &index,
                tf: &gtf,
                scene: &sc,
                views: &[view],
                settings: &settings,
            },
        )
        .unwrap();
    let reference = reference::render(&s.vol, f, &sc.placement, &view, Tolerance::default());
    let image = out.images.remove(0);
    let (rmse, max) = support::error(&image, &reference);
    let mean_alpha = reference.iter().map(|p| p[3]).sum::<f64>() / reference.len() as f64;
    Measured {
        image,
        reference,
        rmse,
        max,
        mean_alpha,
        running_integral: gtf.uses_running_integral(),
        end_path: gtf.uses_end_path(),
        closed_form: gtf.has_closed_form(),
        feedback: out.feedback,
    }
}

#[test]
fn full_detail_matches_the_reference_integral() {
    full_detail(Filtering::Exact, 1e-3);
}

/// The texture unit's trilinear weights may be of limited precision (many
/// GPUs use 8-bit fixed-point weights). Bound set on llvmpipe, which filters
/// r32float with f32 weights and measures the same error as the exact path
/// (Shepp–Logan 8.1e-4); the margin is for GPUs with coarser weights.
#[test]
fn hardware_filtering_error_is_bounded() {
    full_detail(Filtering::Hardware, 2e-3);
}

fn full_detail(filtering: Filtering, bound: f64) {
    let gpu = Gpu::new().unwrap();
    eprintln!("adapter: {} ({:?})", gpu.info.name, gpu.info.device_type);
    let mut rc = Raycaster::new(&gpu, true, filtering).unwrap();
    for kind in [
        SynthKind::MarschnerLobb,
        SynthKind::Shells,
        SynthKind::SheppLogan,
    ] {
        let s = setup(kind, 40, BrickEncoding::F32);
        let f = tf();
        let (cut, pool) = full_cut(&gpu, &s.db, true);
        let m = measure(&gpu, &mut rc, &s, &f, &cut, &pool, Path::End);
        assert!(m.end_path, "the test transfer function allows the end path");
        let (out, want, e, mx, mean_a) = (m.image, m.reference, m.rmse, m.max, m.mean_alpha);
        let feedback = m.feedback;
        eprintln!("{filtering:?} {kind:?}: RMSE {e:.2e}, max {mx:.2e}, mean opacity {mean_a:.3}");
        if let Ok(dir) = std::env::var("PARALLAX_TEST_IMAGES") {
            let d = std::path::Path::new(&dir);
            let w: Vec<[f32; 4]> = want.iter().map(|p| p.map(|x| x as f32)).collect();
            let diff: Vec<[f32; 4]> = out
                .iter()
                .zip(&w)
                .map(|(a, b)| std::array::from_fn(|c| (a[c] - b[c]).abs() * 10.0))
                .collect();
            parallax_backend::output::write_png(&d.join(format!("{kind:?}-gpu.png")), 40, 32, &out)
                .unwrap();
            parallax_backend::output::write_png(&d.join(format!("{kind:?}-ref.png")), 40, 32, &w)
                .unwrap();
            parallax_backend::output::write_png(
                &d.join(format!("{kind:?}-diff.png")),
                40,
                32,
                &diff,
            )
            .unwrap();
        }
        assert!(mean_a > 0.05, "the view sees the volume");
        assert!(e <= bound, "{filtering:?} {kind:?}: RMSE {e}");
        assert!(out.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
        assert!(feedback.iter().any(|&f| f != 0));
    }
}

/// In a constant volume every pixel's opacity is 1 − exp(−τ·L), L the path
/// length inside the box: any segment skipped or counted twice by the
/// traversal shows.
#[test]
fn traversal_covers_every_path_exactly_once() {
    let gpu = Gpu::new().unwrap();
    let mut rc = Raycaster::new(&gpu, true, Filtering::Exact).unwrap();
    let dims = [37, 29, 45];
    let vol = Volume::from_fn(dims, [1.0, 1.5, 0.8], VoxelType::U8, |_, _, _| 100.0);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &path,
        "c",
        &ImportOptions {
            brick: 8,
            encoding: BrickEncoding::F32,
            ..Default::default()
        },
    )
    .unwrap();
    let db = OctreeDb::open(&path).unwrap();
    let tau = 0.05;
    let f =
        TransferFunction::from_points(vec![ControlPoint::new(0.0, [1.0, 0.5, 0.25], tau)]).unwrap();
    let table = PreintTable::new(&f, 0.0, 255.0, 255).unwrap();
    let gtf = TfTable::new(&gpu, &table, &f);
    let (cut, pool) = full_cut(&gpu, &db, true);
    let index = SpatialIndex::build(db.layout(), &cut, (100.0, 100.0)).unwrap();
    for rot in [
        [0.0, 0.0, 0.0],
        [20.0, 35.0, 0.0],
        [45.0, 45.0, 45.0],
        [0.0, 90.0, 0.0],
    ] {
        let sc = SceneGeometry::new(
            Placement {
                center: [0.0, 0.0, 0.0],
                rotation_deg: rot,
                size: 0.3,
            },
            *db.layout(),
            db.header.info.spacing,
        );
        let view = View::window([48, 40], [0.4, 0.33], [0.03, -0.02, 0.7]);
        let out = rc
            .render(
                &gpu,
                &RenderInputs {
                    pool: &pool,
                    index: &index,
                    tf: &gtf,
                    scene: &sc,
                    views: &[view],
                    settings: &RenderSettings {
                        step_factor: 0.5,
                        early_termination: 1.0,
                        shading: false,
                        ..Default::default()
                    },
                },
            )
            .unwrap();
        let mut worst = 0f64;
        for j in 0..40 {
            for i in 0..48 {
                let (o, d) = view.ray(i, j);
                let (vo, vd) = sc.placement.ray_to_volume(sc.extent(), o, d);
                let len = reference::clip_to_box(vo, vd, glam::DVec3::from(sc.extent()))
                    .map(|(a, b)| b - a)
                    .unwrap_or(0.0);
                let want = 1.0 - (-tau * len).exp();
                let got = out.images[0][(j * 48 + i) as usize][3] as f64;
                worst = worst.max((got - want).abs());
            }
        }
        eprintln!("rotation {rot:?}: worst opacity error {worst:.2e}");
        assert!(worst < 1e-4, "rotation {rot:?}: {worst}");
    }
}

/// The GPU pre-integrates from the segments' ends where the transfer
/// function's range allows (each sample reads its bin once), otherwise per
/// segment, summing whole bins by the running integral or, for extreme
/// ranges, by the dyadic pyramid; every path matches the reference, and on
/// the same transfer function the end path and the per-segment path give
/// the same image; the 2D table (`preintegration = "2d"`, bilinear between
/// its nodes, here the 1D table's own) matches within the same bound. The
/// second transfer function spans 1e-4…0.3 per unit
/// (a running integral, too wide for f32 partial bins), the third 1e-6…0.3,
/// which forces the pyramid.
#[test]
fn every_table_path_matches_the_reference() {
    let gpu = Gpu::new().unwrap();
    let mut rc = Raycaster::new(&gpu, true, Filtering::Exact).unwrap();
    let s = setup(SynthKind::Shells, 40, BrickEncoding::F32);
    let (cut, pool) = full_cut(&gpu, &s.db, true);
    let spanning = |low: f64| {
        TransferFunction::from_points(vec![
            ControlPoint::new(0.0, [0.2, 0.2, 0.2], low),
            ControlPoint::new(90.0, [0.2, 0.2, 0.2], low),
            ControlPoint::new(160.0, [1.0, 0.3, 0.1], 0.08),
            ControlPoint::new(255.0, [0.5, 0.7, 1.0], 0.3),
        ])
        .unwrap()
    };
    let mut by_end = None;
    for (f, path, prefix, name) in [
        (tf(), Path::End, true, "end path"),
        (tf(), Path::Segment, true, "per segment, running integral"),
        (tf(), Path::Grid, true, "2D table"),
        (
            spanning(1e-4),
            Path::End,
            true,
            "wide range: running integral",
        ),
        (spanning(1e-6), Path::End, false, "extreme range: pyramid"),
        (spanning(1e-6), Path::Grid, false, "extreme range: 2D table"),
        (tf(), Path::Analytic, true, "closed form"),
        (
            spanning(1e-6),
            Path::Analytic,
            false,
            "extreme range: closed form",
        ),
    ] {
        let m = measure(&gpu, &mut rc, &s, &f, &cut, &pool, path);
        assert_eq!(m.running_integral, prefix, "{name}");
        assert_eq!(m.end_path, name == "end path", "{name}");
        let (e, mx, mean_a) = (m.rmse, m.max, m.mean_alpha);
        eprintln!("{name}: RMSE {e:.2e}, max {mx:.2e}, mean opacity {mean_a:.3}");
        assert!(mean_a > 0.02);
        assert!(e <= 1e-3, "{name}: RMSE {e}");
        if m.end_path {
            by_end = Some(m.image);
        } else if let (Some(first), true) = (&by_end, name.starts_with("per segment")) {
            let first: Vec<[f64; 4]> = first.iter().map(|p| p.map(|x| x as f64)).collect();
            let (d, dmax) = support::error(&m.image, &first);
            eprintln!("end path against per segment: RMSE {d:.2e}, max {dmax:.2e}");
            assert!(dmax < 2e-6, "the two sums differ by {dmax}");
        } else if let (Some(first), true) = (&by_end, name == "closed form") {
            // The same exact integral by another formula: the images agree
            // to f32 rounding.
            let first: Vec<[f64; 4]> = first.iter().map(|p| p.map(|x| x as f64)).collect();
            let (d, dmax) = support::error(&m.image, &first);
            eprintln!("end path against closed form: RMSE {d:.2e}, max {dmax:.2e}");
            assert!(dmax < 1e-5, "the two integrals differ by {dmax}");
        }
        if path == Path::Analytic {
            assert!(m.closed_form, "{name}: no closed form");
        }
    }
}
