//! Thick slices at the default accuracy: a CT-like phantom with 0.5 × 0.5 ×
//! 4 mm voxels must be rendered about as accurately as the same phantom
//! with isotropic voxels (`parallax bench --anisotropy` at full size).

use parallax_backend::bench::anisotropy_study;
use parallax_common::config::RenderConfig;

#[test]
fn thick_slices_are_refined_like_isotropic_voxels() {
    let dir = tempfile::tempdir().unwrap();
    // 64 mm: 64³ against 128 × 128 × 16; a 1 mm voxel is about 0.6 pixels.
    let points = anisotropy_study(dir.path(), 64, [96, 72], 0.16).unwrap();
    let find = |aniso: bool, accuracy: f64| {
        points
            .iter()
            .find(|p| (p.spacing[2] > 1.0) == aniso && p.accuracy == accuracy)
            .unwrap()
    };
    let default = RenderConfig::default().accuracy;
    let (iso, aniso) = (find(false, default), find(true, default));
    let aniso_full = find(true, 0.01);
    eprintln!(
        "default accuracy: isotropic RMSE {:.2e} ({} bricks), thick slices {:.2e} ({} bricks); \
         thick slices at full detail {:.2e} ({} bricks)",
        iso.rmse, iso.bricks, aniso.rmse, aniso.bricks, aniso_full.rmse, aniso_full.bricks
    );
    assert!(iso.rmse > 0.0 && iso.rmse < 1e-3);
    assert!(
        aniso.rmse <= 2.0 * iso.rmse,
        "{} vs {}",
        aniso.rmse,
        iso.rmse
    );
    assert!(aniso.rmse <= 2.0 * aniso_full.rmse);
    assert!(dir.path().join("anisotropy.csv").exists());
}
