//! Fixtures shared by the back end's integration tests.
#![allow(dead_code)]

use parallax_backend::data::synth::{synth_value, SynthKind};
use parallax_backend::store::BrickEncoding;
use parallax_backend::store::{self, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::config::{Interpolation, RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;

/// An n³ procedural volume, 8 bit, 1 mm voxels.
pub fn synth_u8(kind: SynthKind, n: usize) -> Volume {
    Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        (synth_value(kind, i, j, k, n) * 255.0).round() as f32
    })
}

/// n³ Marschner–Lobb, 8 bit.
pub fn marschner_lobb(n: usize) -> Volume {
    synth_u8(SynthKind::MarschnerLobb, n)
}

/// Imports an in-memory volume into `path`.
pub fn import_volume(vol: &Volume, path: &Path, brick: usize, encoding: BrickEncoding) {
    store::import(
        &mut MemorySource::new(vol),
        path,
        "test volume",
        &ImportOptions {
            brick,
            encoding,
            ..Default::default()
        },
    )
    .unwrap();
}

/// RMSE and max abs of premultiplied RGBA against a reference image.
pub fn error(img: &[[f32; 4]], reference: &[[f64; 4]]) -> (f64, f64) {
    assert_eq!(img.len(), reference.len());
    let (rmse, max, _) = parallax_backend::bench::image_error(img, reference);
    (rmse, max)
}

/// A translucent transfer function over 0..255: clear below 80, three
/// coloured materials above.
pub fn translucent() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0, 0.0, 0.0], 0.0),
        ControlPoint::new(80.0, [0.9, 0.5, 0.2], 0.0),
        ControlPoint::new(140.0, [0.9, 0.6, 0.3], 0.08),
        ControlPoint::new(200.0, [0.3, 0.6, 1.0], 0.02),
        ControlPoint::new(255.0, [1.0, 1.0, 1.0], 0.3),
    ])
    .unwrap()
}

/// Mean opacity of an image.
pub fn mean_alpha(a: &[[f32; 4]]) -> f64 {
    a.iter().map(|p| p[3] as f64).sum::<f64>() / a.len().max(1) as f64
}

/// Premultiplied RGBA: finite, no negative value, nothing above 1.
pub fn assert_valid(what: &str, img: &[[f32; 4]]) {
    for (i, p) in img.iter().enumerate() {
        assert!(
            p.iter()
                .all(|v| v.is_finite() && *v >= 0.0 && *v <= 1.0 + 1e-6),
            "{what}: pixel {i} = {p:?}"
        );
    }
}

/// Plain DVR, no shading, full-length rays, every leaf at full resolution,
/// bricks interpolated with exact f32 weights (not by the texture unit):
/// what the reference integral is compared with.
pub fn exact_config() -> RenderConfig {
    RenderConfig {
        shading: Shading::None,
        step_factor: 0.125,
        early_termination: 1.0,
        accuracy: 0.01,
        visibility_feedback: false,
        interpolation: Interpolation::Exact,
        ..RenderConfig::default()
    }
}

/// The Colin27 head MRI of Debian's mricron-data.
pub const COLIN27: &str = "/usr/share/mricron/templates/ch2.nii.gz";

/// The repository's configs/ folder.
pub fn configs() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

/// Imports the file `src` into the database `db`.
pub fn import_file(src: &Path, db: &Path, encoding: BrickEncoding) {
    store::import(
        parallax_backend::data::open(src, None).unwrap().as_mut(),
        db,
        "test volume",
        &ImportOptions {
            encoding,
            ..Default::default()
        },
    )
    .unwrap();
}

/// Colin27 imported into `dir`, or `None` (said on stderr) where the file
/// is not installed.
pub fn colin27(dir: &Path, encoding: BrickEncoding) -> Option<std::path::PathBuf> {
    if !Path::new(COLIN27).exists() {
        eprintln!("SKIPPED: {COLIN27} is not installed (apt: mricron-data)");
        return None;
    }
    let db = dir.join("colin.pxo");
    import_file(Path::new(COLIN27), &db, encoding);
    Some(db)
}

/// The head upright, face to the viewer, 25 cm tall.
pub fn colin_placement() -> parallax_common::camera::Placement {
    parallax_common::camera::Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [-90.0, 180.0, 0.0],
        size: 0.25,
    }
}
