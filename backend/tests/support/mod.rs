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
    let e = parallax_backend::metric::image_error(img, reference);
    (e.rmse, e.max_abs)
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
/// what the reference integral is compared with. The step is 1/8 of a
/// voxel: accuracy 0.01 (sub-pixel) takes a quarter of `step_factor` at the
/// finest level, so a test that sets `step_factor` gets a quarter of it.
pub fn exact_config() -> RenderConfig {
    RenderConfig {
        shading: Shading::None,
        step_factor: 0.5,
        early_termination: 1.0,
        accuracy: 0.01,
        visibility_feedback: false,
        interpolation: Interpolation::Exact,
        ..RenderConfig::default()
    }
}

/// [`exact_config`] stepping `step` voxels at the finest level.
pub fn exact_at(step: f64) -> RenderConfig {
    RenderConfig {
        step_factor: step / 0.25,
        ..exact_config()
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

/// A scene a renderer switch must not change.
pub struct Case<'a> {
    pub what: &'a str,
    pub db: &'a Path,
    pub tf: &'a TransferFunction,
    pub tools: &'a [parallax_common::tools::Tool],
    pub placement: parallax_common::camera::Placement,
    pub views: &'a [parallax_common::camera::View],
    pub cfg: RenderConfig,
}

/// Renders the converged frame of `c` (with frame reconstruction, the four
/// sub-frames of the converged cut) with a switch on and off (`set`);
/// asserts that the volume is visible and that every view's image is the
/// same bit for bit. Returns the two frames' figures (on, off) and the
/// lit pixels out of all.
pub fn unchanged_by(
    c: &Case,
    switch: &str,
    set: impl Fn(&mut parallax_backend::render::Renderer, bool),
) -> (
    parallax_common::protocol::FrameStats,
    parallax_common::protocol::FrameStats,
    usize,
    usize,
) {
    let run = |on: bool| {
        let mut r = parallax_backend::render::Renderer::new(c.db, &c.cfg).unwrap();
        r.set_transfer_function(1, c.tf).unwrap();
        r.set_tools(1, c.tools).unwrap();
        set(&mut r, on);
        let mut f = r.converge(&c.placement, c.views, &c.cfg, 64).unwrap();
        if c.cfg.reconstruction {
            for k in 0..4 {
                f = r.frame(100 + k, &c.placement, c.views, &c.cfg).unwrap();
            }
        }
        f
    };
    let (on, off) = (run(true), run(false));
    let pixels: usize = on.images.iter().map(Vec::len).sum();
    let lit: usize = on
        .images
        .iter()
        .map(|img| img.iter().filter(|p| p[3] > 0.01).count())
        .sum();
    assert!(lit > pixels / 20, "{}: the volume is visible", c.what);
    for (a, b) in on.images.iter().zip(&off.images) {
        let differing = a
            .iter()
            .zip(b)
            .filter(|(p, q)| p.map(f32::to_bits) != q.map(f32::to_bits))
            .count();
        assert_eq!(differing, 0, "{}: pixels that differ with {switch}", c.what);
    }
    (on.stats, off.stats, lit, pixels)
}

/// Multi-centre views of a light field display (G10 Eq. 1) onto the
/// Colin27 head, one per eye x (m), `px` pixels square.
pub fn colin27_lightfield(eyes: &[f64], px: u32) -> Vec<parallax_common::camera::View> {
    eyes.iter()
        .map(|&ex| parallax_common::camera::View {
            resolution: [px, px],
            region: [-0.15, -0.15, 0.3, 0.3],
            eye: [ex, 0.0, 1.5],
            observer: [0.1, 0.02, 0.9],
            eta: 1.0,
        })
        .collect()
}

/// Colin27's opaque skin and translucent brain (configs/tf/).
pub fn colin27_tfs() -> (TransferFunction, TransferFunction) {
    let load = |f: &str| TransferFunction::load(configs().join("tf").join(f)).unwrap();
    (load("colin27-skin.toml"), load("colin27-brain.toml"))
}

/// A clip plane through the head's middle with a 1 cm band of emphasis.
pub fn clip_plane() -> [parallax_common::tools::Tool; 1] {
    [parallax_common::tools::Tool::ClipPlane(
        parallax_common::tools::ClipPlane {
            point: [0.0, 0.0, 0.02],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.01,
            context: [0.3, 0.7],
        },
    )]
}

/// The 96³ CT phantom (i16 Hounsfield units) imported into `dir`, with the
/// CT-Bone preset.
pub fn ct_bone(dir: &Path, encoding: BrickEncoding) -> (std::path::PathBuf, TransferFunction) {
    let src = dir.join("ct.nrrd");
    parallax_backend::data::write_synth(
        parallax_backend::data::SynthKind::Ct,
        96,
        VoxelType::I16,
        &src,
        |_| {},
    )
    .unwrap();
    let db = dir.join("ct.pxo");
    import_file(&src, &db, encoding);
    let tf = TransferFunction::load(configs().join("tf/ct-bone.toml")).unwrap();
    (db, tf)
}

/// The CT phantom turned to show its bones, 25 cm across.
pub fn ct_placement() -> parallax_common::camera::Placement {
    parallax_common::camera::Placement {
        center: [0.0; 3],
        rotation_deg: [-70.0, 30.0, 0.0],
        size: 0.25,
    }
}

/// The converged image of `view` with `tools` (40 frames at most), checked
/// finite and in [0, 1].
pub fn render_tools(
    db: &Path,
    tf: &TransferFunction,
    tools: &[parallax_common::tools::Tool],
    placement: &parallax_common::camera::Placement,
    view: &parallax_common::camera::View,
    cfg: &RenderConfig,
) -> Vec<[f32; 4]> {
    let mut r = parallax_backend::render::Renderer::new(db, cfg).unwrap();
    r.set_transfer_function(1, tf).unwrap();
    r.set_tools(1, tools).unwrap();
    let mut f = r.converge(placement, &[*view], cfg, 40).unwrap();
    assert_valid("render", &f.images[0]);
    f.images.remove(0)
}
