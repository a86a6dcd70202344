//! Thick slices at the default accuracy: a CT-like phantom with 0.5 × 0.5 ×
//! 4 mm voxels must be rendered about as accurately as the same phantom
//! with isotropic voxels of its in-plane size (`parallax bench anisotropy`
//! at full size), within 1e-2 of its exact integral; where the view is far,
//! levels that halve the finer axes first must serve it with fewer bricks
//! than levels that halve all three; `accuracy` from 0.25 to 16 moves
//! through its levels, error and bricks monotone (and below 1, where the
//! finest level covers more pixels than asked, its step); and seen along the
//! slices' normal, the step follows the thick edge (issue 40).

use parallax_bench::anisotropy::anisotropy_study;
use parallax_common::config::RenderConfig;

#[test]
fn thick_slices_are_refined_like_isotropic_voxels() {
    let dir = tempfile::tempdir().unwrap();
    // 64 mm: 64³ against 128 × 128 × 16; near, a 1 mm voxel is about 0.6
    // pixels, far 0.15.
    let points = anisotropy_study(dir.path(), 64, [96, 72], 0.16).unwrap();
    let find_ml = |volume: &str, view: &str, accuracy: f64, multilevel: bool| {
        points
            .iter()
            .find(|p| {
                p.volume == volume
                    && p.view == view
                    && p.accuracy == accuracy
                    && p.multilevel == multilevel
            })
            .unwrap_or_else(|| panic!("{volume}, {view}, accuracy {accuracy}"))
    };
    let find = |volume: &str, view: &str, accuracy: f64| find_ml(volume, view, accuracy, false);
    let default = RenderConfig::default().accuracy;
    for view in ["near", "far"] {
        let iso = find("isotropic 0.5 mm", view, default);
        let aniso = find("0.5 x 0.5 x 4 mm slices", view, default);
        let all_axes = find(
            "0.5 x 0.5 x 4 mm slices (levels halving all axes)",
            view,
            default,
        );
        let full = find("0.5 x 0.5 x 4 mm slices", view, 0.01);
        eprintln!(
            "{view}, default accuracy: isotropic RMSE {:.2e} ({} bricks), thick slices {:.2e} \
             ({} bricks), in levels halving all axes {:.2e} ({} bricks); at full detail {:.2e} \
             ({} bricks)",
            iso.rmse,
            iso.bricks,
            aniso.rmse,
            aniso.bricks,
            all_axes.rmse,
            all_axes.bricks,
            full.rmse,
            full.bricks
        );
        assert!(iso.rmse > 0.0 && iso.rmse < 3e-2);
        // The default on thick slices stays within 1e-2 of the exact
        // integral.
        assert!(aniso.rmse < 1e-2, "{view}: {}", aniso.rmse);
        assert!(
            aniso.rmse <= 2.0 * iso.rmse,
            "{view}: {} vs {}",
            aniso.rmse,
            iso.rmse
        );
        assert!(aniso.bricks <= all_axes.bricks && aniso.bricks <= full.bricks);
        // Multilevel sampling blends each leaf with its parent and
        // grandparent, whose voxels are coarser along x and y only (a
        // parent read at the wrong place would show as errors of the order
        // of the image): as accurate as on isotropic voxels.
        let ml = find_ml("0.5 x 0.5 x 4 mm slices", view, default, true);
        let ml_iso = find_ml("isotropic 0.5 mm", view, default, true);
        eprintln!(
            "{view}, multilevel: RMSE {:.2e} ({} bricks), isotropic {:.2e} ({} bricks)",
            ml.rmse, ml.bricks, ml_iso.rmse, ml_iso.bricks
        );
        assert!(
            ml.rmse.is_finite() && ml.rmse <= 2.0 * ml_iso.rmse,
            "{ml:?} {ml_iso:?}"
        );
        // `accuracy` moves error and bricks monotonically, through more
        // than the finest level and one other.
        let sweep: Vec<_> = parallax_bench::anisotropy::ACCURACY_SWEEP
            .iter()
            .map(|&a| find("0.5 x 0.5 x 4 mm slices", view, a))
            .collect();
        for w in sweep.windows(2) {
            eprintln!(
                "{view}: accuracy {} → {}: RMSE {:.2e} → {:.2e}, bricks {} → {}",
                w[0].accuracy, w[1].accuracy, w[0].rmse, w[1].rmse, w[0].bricks, w[1].bricks
            );
            assert!(
                w[1].bricks <= w[0].bricks && w[1].rmse >= w[0].rmse * 0.999,
                "{view}: accuracy {} → {} is not monotone",
                w[0].accuracy,
                w[1].accuracy
            );
        }
        let mut distinct: Vec<u64> = sweep.iter().map(|p| p.bricks).collect();
        distinct.dedup();
        // Distinct points of the work–precision plot: a coarser cut, or
        // (at the finest level, below accuracy 1) a finer step.
        let points = 1 + sweep
            .windows(2)
            .filter(|w| w[1].bricks != w[0].bricks || w[1].rmse > w[0].rmse * 1.001)
            .count();
        eprintln!("{view}: {points} distinct points over accuracy 0.25-16, cuts {distinct:?}");
        if view == "near" {
            assert!(
                distinct.len() >= 3,
                "near: bricks over the sweep {distinct:?}"
            );
            // Accuracy 0.25 asks for more than the finest level's voxels
            // (0.3 pixels) give: its step shrinks (sub-pixel accuracy).
            assert!(
                sweep[1].rmse > 1.2 * sweep[0].rmse,
                "near: accuracy 0.25 {:.2e} against 0.5 {:.2e}",
                sweep[0].rmse,
                sweep[1].rmse
            );
            assert!(points >= 4, "near: {points} distinct points");
        }
        if view == "far" {
            assert!(
                aniso.bricks < all_axes.bricks,
                "far: {} bricks against {} with levels halving all axes",
                aniso.bricks,
                all_axes.bricks
            );
        }
    }
    // Seen along the slices' normal, the step follows the voxel in the
    // ray's direction (the thick edge; before, the thinnest): the thick
    // slices take far fewer samples than the isotropic 0.5 mm phantom for
    // as accurate an image.
    let iso = find("isotropic 0.5 mm", "axial", default);
    let thick = find("0.5 x 0.5 x 4 mm slices", "axial", default);
    eprintln!(
        "axial, default accuracy: isotropic 0.5 mm RMSE {:.2e}, {} samples; thick slices RMSE {:.2e}, {} samples ({:.2} of the isotropic's)",
        iso.rmse,
        iso.samples,
        thick.rmse,
        thick.samples,
        thick.samples as f64 / iso.samples as f64
    );
    assert!(iso.samples > 0 && thick.samples > 0);
    assert!(
        (thick.samples as f64) < 0.4 * iso.samples as f64,
        "axial: {} samples against {}",
        thick.samples,
        iso.samples
    );
    assert!(
        thick.rmse.is_finite() && thick.rmse <= 2.0 * iso.rmse,
        "axial: RMSE {} against {}",
        thick.rmse,
        iso.rmse
    );
    assert!(dir.path().join("anisotropy.csv").exists());
}
