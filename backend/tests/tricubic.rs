//! Tricubic B-spline filtering (L12 §5.1, eight trilinear lookups a
//! sample): it reproduces linear data exactly, so on a ramp it renders the
//! trilinear image; on Marschner–Lobb it smooths; the texture unit's
//! lookups and exact ones give the same image.

mod support;
use parallax_backend::render::Renderer;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Filter, Interpolation, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;
use support::{assert_valid, error, exact_config, import_volume, marschner_lobb, translucent};

fn render(db: &Path, tf: &TransferFunction, cfg: &RenderConfig) -> Vec<[f32; 4]> {
    let placement = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [20.0, 35.0, 0.0],
        size: 0.2,
    };
    let view = View::window([64, 48], [0.4, 0.3], [0.0, 0.0, 0.8]);
    let mut r = Renderer::new(db, cfg).unwrap();
    r.set_transfer_function(1, tf).unwrap();
    r.converge(&placement, &[view], cfg, 64).unwrap().images[0].clone()
}

fn as_f64(img: &[[f32; 4]]) -> Vec<[f64; 4]> {
    img.iter().map(|p| p.map(|v| v as f64)).collect()
}

#[test]
fn tricubic_reproduces_linear_data_and_smooths_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let n = 32;
    // A ramp along x; the transfer function sees only its middle half, so
    // no ray samples where the brick's edge padding bends it.
    let ramp = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::F32, |i, _, _| {
        (i as f32 + 0.5) / n as f32
    });
    let ramp_db = dir.path().join("ramp.pxo");
    import_volume(&ramp, &ramp_db, 16, BrickEncoding::F32);
    let window = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(0.3, [0.2, 0.4, 0.9], 0.0),
        ControlPoint::new(0.5, [0.9, 0.6, 0.3], 0.2),
        ControlPoint::new(0.7, [1.0, 0.9, 0.5], 0.0),
        ControlPoint::new(1.0, [0.0; 3], 0.0),
    ])
    .unwrap();
    let trilinear = exact_config();
    let tricubic = RenderConfig {
        filter: Filter::Tricubic,
        ..exact_config()
    };
    let tricubic_hw = RenderConfig {
        interpolation: Interpolation::Hardware,
        ..tricubic.clone()
    };
    let a = render(&ramp_db, &window, &trilinear);
    let b = render(&ramp_db, &window, &tricubic);
    let c = render(&ramp_db, &window, &tricubic_hw);
    for (what, img) in [
        ("trilinear", &a),
        ("tricubic", &b),
        ("tricubic, texture unit", &c),
    ] {
        assert_valid(what, img);
    }
    let (ramp_rmse, ramp_max) = error(&b, &as_f64(&a));
    let (hw_rmse, hw_max) = error(&c, &as_f64(&b));
    let opacity = a.iter().map(|p| p[3] as f64).fold(0.0, f64::max);
    eprintln!(
        "ramp: tricubic against trilinear RMSE {ramp_rmse:.2e} (max {ramp_max:.2e}); texture \
         unit against exact lookups {hw_rmse:.2e} (max {hw_max:.2e}); largest opacity {opacity:.2}"
    );
    assert!(opacity > 0.3, "the ramp is seen");
    assert!(ramp_rmse < 1e-4, "{ramp_rmse}");
    assert!(hw_rmse < 2e-3, "{hw_rmse}");

    // Marschner–Lobb: the B-spline smooths what trilinear keeps.
    let ml_db = dir.path().join("ml.pxo");
    import_volume(&marschner_lobb(32), &ml_db, 16, BrickEncoding::F32);
    let tf = translucent();
    let a = render(&ml_db, &tf, &trilinear);
    let b = render(&ml_db, &tf, &tricubic);
    assert_valid("tricubic Marschner-Lobb", &b);
    let (ml_rmse, _) = error(&b, &as_f64(&a));
    // Smoother: the image varies less from pixel to pixel.
    let roughness = |img: &[[f32; 4]]| {
        img.windows(2)
            .map(|w| {
                (0..4)
                    .map(|c| (w[1][c] - w[0][c]).abs() as f64)
                    .sum::<f64>()
            })
            .sum::<f64>()
    };
    let (ra, rb) = (roughness(&a), roughness(&b));
    eprintln!(
        "Marschner-Lobb: tricubic against trilinear RMSE {ml_rmse:.2e}; pixel-to-pixel \
         variation {rb:.3} against {ra:.3}"
    );
    assert!(ml_rmse > 10.0 * ramp_rmse.max(1e-5), "{ml_rmse}");
    assert!(rb < ra, "{rb} vs {ra}");
}
