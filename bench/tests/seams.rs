//! Multilevel sampling (G10 §4, Fig. 5): where the cut changes level
//! between bricks, one level of detail per brick leaves a step in the image
//! that the full-detail image does not have; blending levels by the view's
//! footprint removes it (`parallax bench seams` at twice the size).

use parallax_bench::seams::seam_study;

#[test]
fn multilevel_sampling_removes_the_steps_at_level_changes() {
    let dir = tempfile::tempdir().unwrap();
    let points = seam_study(dir.path(), 64, [192, 144]).unwrap();
    let mixed = points
        .iter()
        .find(|p| p.accuracy == 8.0)
        .expect("accuracy 8 studied");
    eprintln!("{mixed:?}");
    // The cut mixes levels: coarse bricks at the far end, a seam across the
    // slab.
    assert!(mixed.bricks < 16, "{mixed:?}");
    assert!(mixed.seam_pairs >= 50, "{mixed:?}");
    // One level per brick: a step of about 1e-2 along the seam.
    assert!(mixed.jump_before > 5e-3, "{mixed:?}");
    // Multilevel sampling: none (what is left is below a tenth).
    assert!(
        mixed.jump_after < 0.1 * mixed.jump_before,
        "{} → {}",
        mixed.jump_before,
        mixed.jump_after
    );
    for p in &points {
        assert!(p.rmse_before.is_finite() && p.rmse_after.is_finite());
        assert!(p.rmse_after < 0.1, "{p:?}");
    }
    assert!(dir.path().join("seams.csv").exists());
}

/// On a light field display the blend follows s(z) (G10 §4): away from the
/// screen plane the display resolves less, and the samples blend in the
/// coarser levels there; images stay valid.
#[test]
fn multilevel_sampling_follows_the_light_field_resolution() {
    use parallax_backend::loader::LightField;
    use parallax_backend::render::Renderer;
    use parallax_backend::store::{self, BrickEncoding, ImportOptions};
    use parallax_backend::volume::{MemorySource, Volume, VoxelType};
    use parallax_common::camera::{Placement, View};
    use parallax_common::config::{Interpolation, RenderConfig};
    use parallax_common::tf::{ControlPoint, TransferFunction};
    let dir = tempfile::tempdir().unwrap();
    let n = 64;
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::F32, |i, j, k| {
        let w = |i: usize| (std::f64::consts::TAU * (i as f64 + 0.5) / 8.0).sin();
        (0.5 + 0.4 * w(i) * w(j) * w(k)) as f32
    });
    let db = dir.path().join("waves.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &db,
        "waves",
        &ImportOptions {
            brick: 16,
            encoding: BrickEncoding::F32,
            ..Default::default()
        },
    )
    .unwrap();
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.1, 0.3, 0.9], 0.0),
        ControlPoint::new(1.0, [1.0, 0.8, 0.3], 0.3),
    ])
    .unwrap();
    // A projector's view of a volume reaching well behind the screen.
    let placement = Placement {
        center: [0.0, 0.0, -0.1],
        rotation_deg: [20.0, 35.0, 0.0],
        size: 0.3,
    };
    let view = View {
        resolution: [64, 48],
        region: [-0.2, -0.15, 0.4, 0.3],
        eye: [0.1, 0.0, 1.2],
        observer: [0.0, 0.0, 0.8],
        eta: 1.0,
    };
    let mut images = Vec::new();
    for multilevel in [false, true] {
        let cfg = RenderConfig {
            multilevel,
            interpolation: Interpolation::Exact,
            ..RenderConfig::default()
        };
        let mut r = Renderer::new(&db, &cfg).unwrap();
        r.set_lightfield(Some(LightField {
            pixel_size: 0.004,
            angular_accuracy_deg: 1.0,
        }));
        r.set_transfer_function(1, &tf).unwrap();
        let f = r.converge(&placement, &[view], &cfg, 40).unwrap();
        for p in &f.images[0] {
            assert!(p
                .iter()
                .all(|v| v.is_finite() && (0.0..=1.0 + 1e-6).contains(v)));
        }
        images.push(f.images[0].clone());
    }
    let changed = images[0]
        .iter()
        .zip(&images[1])
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0, f32::max))
        .fold(0.0, f32::max);
    let alpha = images[1].iter().map(|p| p[3] as f64).sum::<f64>() / images[1].len() as f64;
    eprintln!(
        "light field: multilevel changes a pixel by up to {changed:.2e}; mean opacity {alpha:.2}"
    );
    assert!(alpha > 0.05, "the view sees the volume");
    assert!(changed > 1e-3, "the far side blends coarser levels");
    assert!(changed < 0.3);
}
