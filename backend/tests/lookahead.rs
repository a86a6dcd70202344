//! The sample loop fetches each sample one pass ahead on pools of float
//! voxels read with the 2D pre-integration table (the kernel's LOOKAHEAD,
//! backend/src/raycast/mod.rs). It must take the same samples in the same
//! order: every image is the one of the plain loop bit for bit, and so is
//! the count of samples, for every stepper that uses the table (the
//! isosurface does not), across mixed levels, and with a tool that cuts
//! segments at its plane.

mod support;
use glam::DVec3;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Mode, Preintegration, RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, TransferFunction};
use support::{
    clip_plane, colin27, colin27_lightfield, colin27_tfs, colin_placement, ct_bone, ct_placement,
    import_volume, unchanged_by, Case,
};

/// Renders the converged frame with and without the lookahead; asserts
/// the images and the samples taken are the same.
fn compare(c: &Case) {
    let (on, off, lit, pixels) = unchanged_by(c, "the lookahead", |r, on| {
        r.lookahead = on;
        r.count_samples = true;
    });
    println!(
        "{}: {} samples with the lookahead, {} without; {lit} of {pixels} pixels lit",
        c.what, on.samples, off.samples
    );
    assert!(off.samples > 0, "{}: samples were counted", c.what);
    assert_eq!(on.samples, off.samples, "{}: samples taken", c.what);
}

/// Segment optics from the 2D pre-integration table.
fn table() -> RenderConfig {
    RenderConfig {
        preintegration: Preintegration::TwoD,
        ..RenderConfig::default()
    }
}

#[test]
fn colin27_images_unchanged_by_the_lookahead() {
    let dir = tempfile::tempdir().unwrap();
    let Some(db) = colin27(dir.path(), BrickEncoding::F32) else {
        return;
    };
    let window = [View::window([128, 128], [0.3, 0.3], [0.0, 0.0, 0.8])];
    let lightfield = colin27_lightfield(&[-0.5, 0.7], 80);
    let (skin, brain) = colin27_tfs();
    let table = table();
    let coarse = RenderConfig {
        step_factor: 2.0,
        early_termination: 0.99,
        ..table.clone()
    };
    let phong = RenderConfig {
        shading: Shading::Phong,
        ..table.clone()
    };
    let mimda = RenderConfig {
        mode: Mode::Mimda,
        ..table.clone()
    };
    let clip = clip_plane();
    let cases = [
        ("brain", &brain, &[][..], &window[..], table.clone()),
        ("brain, coarse", &brain, &[][..], &window[..], coarse),
        (
            "brain, light field",
            &brain,
            &[][..],
            &lightfield[..],
            table.clone(),
        ),
        (
            "brain, clip plane",
            &brain,
            &clip[..],
            &window[..],
            table.clone(),
        ),
        ("brain, MImDA", &brain, &[][..], &window[..], mimda),
        ("skin, Phong", &skin, &[][..], &window[..], phong),
    ];
    for (what, tf, tools, views, cfg) in cases {
        compare(&Case {
            what: &format!("Colin27 {what}"),
            db: &db,
            tf,
            tools,
            placement: colin_placement(),
            views,
            cfg,
        });
    }
}

/// A CT whose cut mixes levels, sampled across them (multilevel).
#[test]
fn multilevel_ct_unchanged_by_the_lookahead() {
    let dir = tempfile::tempdir().unwrap();
    let (db, tf) = ct_bone(dir.path(), BrickEncoding::F32);
    compare(&Case {
        what: "CT phantom, bone, multilevel",
        db: &db,
        tf: &tf,
        tools: &[],
        placement: ct_placement(),
        views: &[View::window([120, 90], [0.4, 0.3], [0.0, 0.0, 0.8])],
        cfg: RenderConfig {
            multilevel: true,
            accuracy: 2.0,
            ..table()
        },
    });
}

/// Refraction: a translucent ball of index 1.4 bends the rays inside it; a
/// bent ray leaves the loop, so the sample fetched ahead along the old
/// direction is never used.
#[test]
fn refraction_unchanged_by_the_lookahead() {
    let dir = tempfile::tempdir().unwrap();
    let n = 40;
    let (c, r) = (n as f64 / 2.0, 13.0);
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        let d = DVec3::new(i as f64 + 0.5 - c, j as f64 + 0.5 - c, k as f64 + 0.5 - c).length();
        let ripple = 20.0 * ((i as f64 * 0.7).sin() * (j as f64 * 0.5).cos());
        ((255.0 * (r - d + 0.5).clamp(0.0, 1.0)) * 0.8 + ripple.max(0.0)).round() as f32
    });
    let db = dir.path().join("ball.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.2, 0.4, 0.9], 0.0).with_refraction(1.0),
        ControlPoint::new(30.0, [0.3, 0.5, 0.9], 0.05).with_refraction(1.0),
        ControlPoint::new(255.0, [1.0, 0.8, 0.5], 0.08).with_refraction(1.4),
    ])
    .unwrap();
    compare(&Case {
        what: "refracting ball",
        db: &db,
        tf: &tf,
        tools: &[],
        placement: Placement {
            center: [0.0; 3],
            rotation_deg: [20.0, 30.0, 0.0],
            size: 0.3,
        },
        views: &[View::window([64, 64], [0.36, 0.36], [0.0, 0.0, 1.5])],
        cfg: RenderConfig {
            refraction: true,
            ..table()
        },
    });
}
