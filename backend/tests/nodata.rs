//! NaN as "no data" (`parallax import --nan empty`): such voxels never show
//! and never blend into their neighbours' interpolation, on the GPU as in the
//! reference integral; bricks with no data at all are never stored.

mod support;

use parallax_backend::reference::{self, Tolerance};
use parallax_backend::render::Renderer;
use parallax_backend::store::{self, BrickEncoding, ImportOptions, OctreeDb};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::tf::{ControlPoint, TransferFunction};
use support::{assert_valid, exact_config, mean_alpha};

const N: usize = 32;

/// Marschner–Lobb-like values on 0..255, with no data in a ball and in the
/// half-space x ≥ 22 (a simulation's outside).
fn holed() -> Volume {
    let ml = support::marschner_lobb(N);
    Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |i, j, k| {
        let d2 = [i, j, k]
            .iter()
            .map(|&c| (c as f64 - 12.0).powi(2))
            .sum::<f64>();
        if i >= 22 || d2 < 25.0 {
            f32::NAN
        } else {
            ml.voxel(i, j, k)
        }
    })
}

fn tf() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.2, 0.3, 0.9], 0.01),
        ControlPoint::new(128.0, [0.9, 0.6, 0.3], 0.06),
        ControlPoint::new(255.0, [1.0, 1.0, 1.0], 0.2),
    ])
    .unwrap()
}

fn import(vol: &Volume, path: &std::path::Path, encoding: BrickEncoding) -> store::ImportReport {
    store::import(
        &mut MemorySource::new(vol),
        path,
        "holed",
        &ImportOptions {
            brick: 8,
            encoding,
            ..Default::default()
        },
    )
    .unwrap()
}

fn render(db: &std::path::Path, placement: &Placement, view: &View) -> Vec<[f32; 4]> {
    let cfg = exact_config();
    let mut r = Renderer::new(db, &cfg).unwrap();
    r.set_transfer_function(1, &tf()).unwrap();
    let f = r.converge(placement, &[*view], &cfg, 30).unwrap();
    assert!(f.stats.adequate);
    f.images[0].clone()
}

#[test]
fn no_data_matches_the_reference_and_is_never_stored() {
    let vol = holed();
    let dir = tempfile::tempdir().unwrap();
    let placement = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [20.0, 35.0, 0.0],
        size: 0.2,
    };
    let view = View::window([48, 36], [0.4, 0.3], [0.0, 0.0, 0.8]);
    let want = reference::render(&vol, &tf(), &placement, &view, Tolerance { abs: 1e-6 });
    assert!(want.iter().flatten().all(|v| v.is_finite()));
    for (encoding, bound) in [(BrickEncoding::F32, 2e-3), (BrickEncoding::U8Range, 4e-3)] {
        let db = dir.path().join(format!("{encoding:?}.pxo"));
        let rep = import(&vol, &db, encoding);
        // The x ≥ 24 bricks of the leaf level (8³; their overlap starts at
        // x = 22) hold no data at all: not stored.
        let o = OctreeDb::open(&db).unwrap();
        let leaf = o.layout().leaf_level() as u8;
        let unstored: Vec<_> = o
            .nodes
            .iter()
            .filter(|n| n.key.level == leaf && !n.is_stored())
            .collect();
        assert!(!unstored.is_empty() && rep.empty >= unstored.len());
        assert_eq!(
            rep.no_data_voxels as usize,
            vol.data.iter().filter(|v| v.is_nan()).count()
        );
        // Decoded bricks keep NaN exactly where the source has it.
        for n in o
            .nodes
            .iter()
            .filter(|n| n.key.level == leaf && n.is_stored())
        {
            let b = o.read_brick(n.key).unwrap().unwrap();
            assert!(b.iter().all(|v| v.is_nan() || (0.0..=255.5).contains(v)));
        }
        let img = render(&db, &placement, &view);
        assert_valid("no data", &img);
        let (rmse, max) = support::error(&img, &want);
        eprintln!(
            "{encoding:?}: RMSE {rmse:.2e}, max {max:.2e}, mean alpha {:.3}",
            mean_alpha(&img)
        );
        assert!(mean_alpha(&img) > 0.05);
        assert!(
            rmse < bound,
            "{encoding:?}: RMSE {rmse} against the reference"
        );
    }
}

/// Looking straight along x through a constant volume whose x ≥ X0 half has
/// no data: the optical depth is τ·L with L the length where a sample has a
/// tap with data, x < (X0 + ½)·s: nothing of the no-data half blends in
/// (a sentinel value would pull samples near the boundary away from the
/// constant, into the transfer function's other values).
#[test]
fn a_boundary_with_no_data_does_not_blend() {
    const X0: usize = 20;
    let c = 100.0;
    let vol = Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |i, _, _| {
        if i >= X0 {
            f32::NAN
        } else {
            c
        }
    });
    // Delta-like: only values within ±2 of c absorb.
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [1.0, 1.0, 1.0], 0.0),
        ControlPoint::new(c as f64 - 2.0, [1.0, 1.0, 1.0], 0.0),
        ControlPoint::new(c as f64, [1.0, 1.0, 1.0], 0.05),
        ControlPoint::new(c as f64 + 2.0, [1.0, 1.0, 1.0], 0.0),
        ControlPoint::new(255.0, [1.0, 1.0, 1.0], 0.0),
    ])
    .unwrap();
    let expected = 1.0 - (-0.05 * (X0 as f64 + 0.5)).exp();
    // Reference: a ray along +x through the middle.
    let o = glam::DVec3::new(-1.0, 16.3, 15.7);
    let got = reference::integrate(&vol, &tf, o, glam::DVec3::X, Tolerance { abs: 1e-9 });
    assert!((got[3] - expected).abs() < 1e-6, "{} vs {expected}", got[3]);

    // The GPU, looking along x (the volume turned so +x faces away).
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("half.pxo");
    import(&vol, &db, BrickEncoding::F32);
    let placement = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [0.0, 90.0, 0.0],
        size: 0.2,
    };
    let view = View::window([16, 12], [0.04, 0.03], [0.0, 0.0, 5.0]);
    let cfg = exact_config();
    let mut r = Renderer::new(&db, &cfg).unwrap();
    r.set_transfer_function(1, &tf).unwrap();
    let f = r.converge(&placement, &[view], &cfg, 30).unwrap();
    let want = reference::render(&vol, &tf, &placement, &view, Tolerance { abs: 1e-7 });
    let centre = (6 * 16 + 8) as usize;
    eprintln!(
        "along x: GPU alpha {:.5}, reference {:.5}, τ·L {:.5}",
        f.images[0][centre][3], want[centre][3], expected
    );
    assert!((want[centre][3] - expected).abs() < 2e-3);
    assert!(
        (f.images[0][centre][3] as f64 - expected).abs() < 5e-3,
        "GPU {} vs {expected}",
        f.images[0][centre][3]
    );
}
