//! Registered layers (a scene's `[[layer]]`s, G10 §4): volumes on the scene
//! volume's grid or placed by a transform, each drawn through its own
//! transfer function and combined
//! with it as media (extinctions and extinction-weighted emissions add).
//! Measured against the exact integral, against the volume alone, and for
//! what they cost when they show nothing. Every test prints the figures it
//! asserts on.

mod support;
use parallax_backend::data;
use parallax_backend::gpu::AdapterRequest;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::render::{Frame, Renderer};
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Layer, LayerTransform, Mode, RenderConfig, ViewOpacity};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::{Path, PathBuf};

/// Writes `tf` as a transfer function file.
fn write_tf(path: &Path, tf: &TransferFunction) -> PathBuf {
    std::fs::write(path, toml::to_string(tf).unwrap()).unwrap();
    path.to_path_buf()
}

fn layer(volume: &Path, tf: &Path) -> Layer {
    Layer {
        volume: volume.to_path_buf(),
        transfer_function: Some(tf.to_path_buf()),
        labels: None,
        opacity: 1.0,
        visible: true,
        view_opacity: None,
        transform: None,
    }
}

/// The converged frame of `db` with `layers`, its own function `tf`.
fn render(
    db: &Path,
    layers: &[Layer],
    tf: &TransferFunction,
    placement: &Placement,
    views: &[View],
    cfg: &RenderConfig,
) -> (Frame, Renderer) {
    let mut r = Renderer::with_layers(db, layers, cfg, &AdapterRequest::from_env(None, 0)).unwrap();
    r.set_transfer_function(1, tf).unwrap();
    let f = r.converge(placement, views, cfg, 64).unwrap();
    (f, r)
}

fn bits_differ(a: &[[f32; 4]], b: &[[f32; 4]]) -> usize {
    a.iter()
        .zip(b)
        .filter(|(p, q)| p.map(f32::to_bits) != q.map(f32::to_bits))
        .count()
}

/// The CT phantom with Slicer's CT-Bone at half extinction drawn with
/// `layers` (the other half), against the whole function: the volume alone
/// and the exact integral, at fine settings. Asserts the bones are in view
/// and the layered image within 1e-3 of the exact integral and within
/// `between` of the volume alone (RMSE); prints the figures after `what`.
fn halves_against_the_whole(
    dir: &Path,
    db: &Path,
    bone: &TransferFunction,
    layers: &[Layer],
    what: &str,
    between: f64,
) {
    let vol = Volume::read_all(data::open(&dir.join("ct.nrrd"), None).unwrap().as_mut()).unwrap();
    let half = bone.scaled_extinction(0.5);
    let placement = support::ct_placement();
    let view = View::window([96, 96], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let cfg = support::exact_config();
    let (whole, _) = render(db, &[], bone, &placement, &[view], &cfg);
    let (layered, r) = render(db, layers, &half, &placement, &[view], &cfg);
    assert_eq!(r.layer_count(), layers.len());
    let (a, b) = (&layered.images[0], &whole.images[0]);
    support::assert_valid(what, a);
    let exact = reference::render(&vol, bone, &placement, &view, Tolerance { abs: 1e-6 });
    let (e_layered, max_layered) = support::error(a, &exact);
    let (e_whole, _) = support::error(b, &exact);
    let alone: Vec<[f64; 4]> = b.iter().map(|p| p.map(f64::from)).collect();
    let (e_between, max_between) = support::error(a, &alone);
    let lit = a.iter().filter(|p| p[3] > 0.05).count();
    println!(
        "{what}: RMSE {e_layered:.2e} (max {max_layered:.2e}) against the exact integral, the volume alone {e_whole:.2e}; between them RMSE {e_between:.2e}, max {max_between:.2e}; {lit} of {} pixels lit; {} bytes read",
        a.len(),
        layered.stats.bytes_read
    );
    assert!(lit > a.len() / 10, "the bones are in view");
    assert!(
        e_layered <= 1e-3,
        "against the exact integral: {e_layered:.2e}"
    );
    assert!(
        e_between <= between,
        "against the volume alone: {e_between:.2e}"
    );
}

/// Two layers of one volume with half its extinction each are that volume
/// with the whole (the averages of τ and k̃ over a segment add): on the CT
/// phantom with Slicer's CT-Bone, at fine settings, against the exact
/// integral of the whole function and against the volume rendered alone.
#[test]
fn two_half_extinction_layers_are_the_whole_volume() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let half_file = write_tf(&dir.path().join("half.toml"), &bone.scaled_extinction(0.5));
    let layers = [layer(&db, &half_file)];
    halves_against_the_whole(
        dir.path(),
        &db,
        &bone,
        &layers,
        "two half-extinction layers",
        1e-4,
    );
}

/// The CT phantom flipped in x and cropped by `crop` voxels at its low y
/// and z edges (and its high x edge), on bricks of 16 instead of 32, and
/// the transform that puts it back on the volume (layer space → the
/// volume's): a layer on another grid whose voxel centres land on the
/// volume's.
fn flipped_and_cropped(vol: &Volume, crop: [usize; 3]) -> (Volume, Vec<[f64; 4]>) {
    let [n0, n1, n2] = vol.info.dims;
    let s = vol.info.spacing;
    let dims = [n0 - crop[0], n1 - crop[1], n2 - crop[2]];
    let mut data = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let (a, b, c) = (n0 - 1 - i, j + crop[1], k + crop[2]);
                data.push(vol.data[(c * n1 + b) * n0 + a]);
            }
        }
    }
    let info = parallax_backend::volume::VolumeInfo {
        dims,
        ..vol.info.clone()
    };
    let transform = vec![
        [-1.0, 0.0, 0.0, n0 as f64 * s[0]],
        [0.0, 1.0, 0.0, crop[1] as f64 * s[1]],
        [0.0, 0.0, 1.0, crop[2] as f64 * s[2]],
    ];
    (Volume::new(info, data), transform)
}

/// A layer on another grid (flipped, cropped, other bricks) placed by its
/// transform: resampled onto the volume's bricks as they are read, it
/// lands on the volume, so two half-extinction layers, one of them
/// placed, are the whole volume against the exact integral and against
/// the volume alone; the layer's bricks are read only where its function
/// sees data; and the same layer without its transform is refused.
#[test]
fn a_layer_on_another_grid_lands_by_its_transform() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let vol = Volume::read_all(
        data::open(&dir.path().join("ct.nrrd"), None)
            .unwrap()
            .as_mut(),
    )
    .unwrap();
    let (moved, transform) = flipped_and_cropped(&vol, [2, 3, 5]);
    let placed_db = dir.path().join("placed.pxo");
    support::import_volume(&moved, &placed_db, 16, BrickEncoding::U8Range);
    let half_file = write_tf(&dir.path().join("half.toml"), &bone.scaled_extinction(0.5));
    let placed = Layer {
        transform: Some(LayerTransform::Matrix(transform)),
        ..layer(&placed_db, &half_file)
    };
    halves_against_the_whole(
        dir.path(),
        &db,
        &bone,
        std::slice::from_ref(&placed),
        "a half layer on another grid (flipped in x, cropped, bricks of 16, 8-bit codes) placed by its transform, the volume at half extinction",
        2e-3,
    );
    let cfg = RenderConfig::default();
    // Without its transform the layer is refused, naming the field.
    let e = Renderer::with_layers(
        &db,
        &[layer(&placed_db, &half_file)],
        &cfg,
        &AdapterRequest::from_env(None, 0),
    )
    .err()
    .map(|e| format!("{e:#}"))
    .expect("refused");
    assert!(e.contains("layer[0].transform"), "{e}");
    // Placed outside the volume, or flattened: refused.
    for (t, want) in [
        (
            vec![
                [1.0, 0.0, 0.0, 500.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
            "outside the scene volume",
        ),
        (
            vec![
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0, 0.0],
            ],
            "singular",
        ),
    ] {
        let l = Layer {
            transform: Some(LayerTransform::Matrix(t)),
            ..placed.clone()
        };
        let e = Renderer::with_layers(&db, &[l], &cfg, &AdapterRequest::from_env(None, 0))
            .err()
            .map(|e| format!("{e:#}"))
            .expect("refused");
        println!("refused: {e}");
        assert!(e.contains("layer[0].transform") && e.contains(want), "{e}");
    }
}

/// A layer whose transfer function is empty over its data costs nothing:
/// the image is the volume's alone bit for bit, none of its bricks is read,
/// and the pool keeps one channel.
#[test]
fn an_empty_layer_changes_no_pixel_and_reads_no_brick() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::U8Range);
    // Extinction only above the data's largest value.
    let empty = TransferFunction::from_points(vec![
        ControlPoint::new(-4000.0, [1.0, 0.0, 0.0], 0.0),
        ControlPoint::new(60000.0, [1.0, 0.0, 0.0], 0.0),
        ControlPoint::new(65000.0, [1.0, 0.0, 0.0], 5.0),
    ])
    .unwrap();
    let empty_file = write_tf(&dir.path().join("empty.toml"), &empty);
    let placement = support::ct_placement();
    let view = View::window([96, 96], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let cfg = RenderConfig::default();
    let (alone, _) = render(&db, &[], &bone, &placement, &[view], &cfg);
    let (with, r) = render(
        &db,
        &[layer(&db, &empty_file)],
        &bone,
        &placement,
        &[view],
        &cfg,
    );
    let differ = bits_differ(&with.images[0], &alone.images[0]);
    println!(
        "an empty layer: {differ} pixels differ; {} bytes read against {} alone; {} layers drawn",
        with.stats.bytes_read,
        alone.stats.bytes_read,
        r.layer_count()
    );
    assert_eq!(r.layer_count(), 0);
    assert_eq!(differ, 0);
    assert_eq!(with.stats.bytes_read, alone.stats.bytes_read);
}

/// A layer is read only where its own function sees data: on a volume
/// whose bright values (250) fill one small ball and whose rest is a dim
/// ramp, a layer that shows only the bright values reads the few bricks
/// around the ball, where the same layer showing the ramp reads all that
/// the volume reads; and the ball adds to the image.
#[test]
fn a_layer_reads_only_the_bricks_its_function_sees() {
    let dir = tempfile::tempdir().unwrap();
    let n = 64;
    let vol = Volume::from_fn([n; 3], [1.0; 3], VoxelType::U8, |i, j, k| {
        let d2 = [i, j, k]
            .iter()
            .map(|&x| (x as f64 - 20.0).powi(2))
            .sum::<f64>();
        if d2 <= 64.0 {
            250.0
        } else {
            (20 + (i + j + k) / 3) as f32
        }
    });
    let db = dir.path().join("ball.pxo");
    support::import_volume(&vol, &db, 16, BrickEncoding::U8Range);
    let ramp = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.3, 0.5, 0.9], 0.0),
        ControlPoint::new(100.0, [0.3, 0.5, 0.9], 0.01),
    ])
    .unwrap();
    let bright = TransferFunction::from_points(vec![
        ControlPoint::new(200.0, [1.0, 0.9, 0.2], 0.0),
        ControlPoint::new(240.0, [1.0, 0.9, 0.2], 0.3),
    ])
    .unwrap();
    let ramp_file = write_tf(&dir.path().join("ramp.toml"), &ramp);
    let bright_file = write_tf(&dir.path().join("bright.toml"), &bright);
    let placement = Placement {
        center: [0.0; 3],
        rotation_deg: [20.0, 35.0, 0.0],
        size: 0.2,
    };
    let view = View::window([96, 96], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let cfg = support::exact_config();
    let run = |layers: &[Layer]| render(&db, layers, &ramp, &placement, &[view], &cfg).0;
    let alone = run(&[]);
    let twice = run(&[layer(&db, &ramp_file)]);
    let with = run(&[layer(&db, &bright_file)]);
    let main = alone.stats.bytes_read;
    let layer_all = twice.stats.bytes_read - main;
    let layer_bright = with.stats.bytes_read - main;
    let alpha = |f: &Frame| support::mean_alpha(&f.images[0]);
    println!(
        "a layer of the bright ball read {layer_bright} bytes of its bricks, one of the ramp {layer_all} (the volume {main}); mean opacity {:.3} alone, {:.3} with the ball's layer",
        alpha(&alone),
        alpha(&with)
    );
    assert_eq!(layer_all, main, "the same function reads the same bricks");
    assert!(
        layer_bright > 0 && layer_bright < main / 3,
        "{layer_bright} of {main}"
    );
    assert!(alpha(&with) > alpha(&alone) + 0.005);
}

/// View-dependent layer opacity (G10 §4): the layer shows fully where a
/// ray's angle to the axis is past the second angle (bit for bit the layer
/// at full opacity), not at all before the first (the volume alone, to the
/// rounding of the layered kernel's interpolation), and in between as the smoothstep says (against the layer at that
/// fixed opacity, for a narrow view whose rays all meet the axis at about
/// one angle).
#[test]
fn view_dependent_opacity_follows_the_smoothstep() {
    let dir = tempfile::tempdir().unwrap();
    // Full precision, so that the volume alone and the layered pool hold
    // the same values (an 8-bit pool keeps codes).
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let soft = TransferFunction::load(support::configs().join("tf/ct-soft-tissue.toml")).unwrap();
    let bone_file = write_tf(&dir.path().join("bone.toml"), &bone);
    let placement = support::ct_placement();
    // A narrow view along −z: every ray within 1.1° of (0, 0, −1), at about
    // 180° to +z.
    let view = View::window([48, 48], [0.03, 0.03], [0.0, 0.0, 0.8]);
    // Layered kernels march without the opaque-segment refinement
    // (`refinement`), so the volume alone is drawn without it too.
    let cfg = RenderConfig {
        refinement: 1,
        ..RenderConfig::default()
    };
    let with = |opacity: f64, view_opacity: Option<ViewOpacity>| {
        let l = Layer {
            opacity,
            view_opacity,
            transform: None,
            ..layer(&db, &bone_file)
        };
        render(&db, &[l], &soft, &placement, &[view], &cfg).0
    };
    let (alone, _) = render(&db, &[], &soft, &placement, &[view], &cfg);
    let full = with(1.0, None);
    let seen = with(
        1.0,
        Some(ViewOpacity {
            axis: [0.0, 0.0, 1.0],
            angles_deg: [150.0, 170.0],
        }),
    );
    let unseen = with(
        1.0,
        Some(ViewOpacity {
            axis: [0.0, 0.0, -1.0],
            angles_deg: [30.0, 60.0],
        }),
    );
    // An axis at 40° to the view's direction, half way between 20° and
    // 60°: smoothstep ½.
    let tilt = 40f64.to_radians();
    let middle = with(
        1.0,
        Some(ViewOpacity {
            axis: [tilt.sin(), 0.0, -tilt.cos()],
            angles_deg: [20.0, 60.0],
        }),
    );
    let half = with(0.5, None);
    let d_seen = bits_differ(&seen.images[0], &full.images[0]);
    let alone_ref: Vec<[f64; 4]> = alone.images[0].iter().map(|p| p.map(f64::from)).collect();
    let (e_unseen, max_unseen) = support::error(&unseen.images[0], &alone_ref);
    let half_ref: Vec<[f64; 4]> = half.images[0].iter().map(|p| p.map(f64::from)).collect();
    let (e_middle, _) = support::error(&middle.images[0], &half_ref);
    let full_ref: Vec<[f64; 4]> = full.images[0].iter().map(|p| p.map(f64::from)).collect();
    let (e_full, _) = support::error(&half.images[0], &full_ref);
    println!(
        "view-dependent opacity: past the angles {d_seen} pixels differ from the layer at full opacity; before them RMSE {e_unseen:.2e} (max {max_unseen:.2e}) from the volume alone (the layered kernel's rounding); half way RMSE {e_middle:.2e} against the layer at opacity ½ (which is {e_full:.2e} from full)"
    );
    assert_eq!(d_seen, 0);
    assert!(
        e_unseen < 2e-5 && max_unseen < 1e-3,
        "{e_unseen:.2e}, max {max_unseen:.2e}"
    );
    assert!(e_full > 1e-3, "the layer shows: {e_full:.2e}");
    assert!(
        e_middle < 0.1 * e_full,
        "{e_middle:.2e} against {e_full:.2e}"
    );
}

/// `tf` with every control point's importance ι set to `importance`.
fn with_importance(tf: &TransferFunction, importance: f64) -> TransferFunction {
    TransferFunction::from_points(
        tf.points()
            .iter()
            .map(|p| p.with_importance(importance))
            .collect(),
    )
    .unwrap()
}

/// MImDA with layers (G10 Eq. 3 over the summed medium): the importance
/// of a segment is each medium's, weighted by its share of the extinction.
/// Two half-extinction layers of one volume with one importance are that
/// volume under MImDA; and a layer carries its own importance: bone as a
/// layer over soft tissue (ι = 0.2) fades the tissue in front of it when
/// its importance is 0.9, and changes nearly nothing at 0.1, against the
/// same scene under DVR.
#[test]
fn mimda_sees_the_combined_medium_and_each_layers_importance() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let placement = support::ct_placement();
    let view = View::window([64, 64], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let mimda = RenderConfig {
        mode: Mode::Mimda,
        gamma: 1.0,
        ..support::exact_config()
    };
    let half = bone.scaled_extinction(0.5);
    let half_file = write_tf(&dir.path().join("half.toml"), &half);
    let (whole, _) = render(&db, &[], &bone, &placement, &[view], &mimda);
    let (halves, _) = render(
        &db,
        &[layer(&db, &half_file)],
        &half,
        &placement,
        &[view],
        &mimda,
    );
    let whole_ref: Vec<[f64; 4]> = whole.images[0].iter().map(|p| p.map(f64::from)).collect();
    let (e_halves, max_halves) = support::error(&halves.images[0], &whole_ref);
    let soft = with_importance(
        &TransferFunction::load(support::configs().join("tf/ct-soft-tissue.toml")).unwrap(),
        0.2,
    );
    let dvr = support::exact_config();
    let importance = |i: f64| {
        let f = write_tf(
            &dir.path().join(format!("bone-{i}.toml")),
            &with_importance(&bone, i),
        );
        let layers = [layer(&db, &f)];
        let under = |cfg: &RenderConfig| render(&db, &layers, &soft, &placement, &[view], cfg).0;
        let (m, d) = (under(&mimda), under(&dvr));
        support::assert_valid("MImDA with a layer", &m.images[0]);
        let d_ref: Vec<[f64; 4]> = d.images[0].iter().map(|p| p.map(f64::from)).collect();
        support::error(&m.images[0], &d_ref).0
    };
    let (e_high, e_low) = (importance(0.9), importance(0.1));
    println!(
        "MImDA (γ = 1) with layers: two half-extinction layers against the whole volume RMSE {e_halves:.2e} (max {max_halves:.2e}); a bone layer of importance 0.9 over soft tissue of 0.2 is {e_high:.2e} from DVR, of importance 0.1 {e_low:.2e}"
    );
    assert!(support::mean_alpha(&whole.images[0]) > 0.05);
    assert!(e_halves < 1e-4, "{e_halves:.2e}");
    assert!(
        e_high > 1e-3 && e_high > 5.0 * e_low,
        "{e_high:.2e}, {e_low:.2e}"
    );
}

/// Bad layers are refused naming the layer's field and file: another grid
/// (without a transform), a corrupt database, a missing transfer function.
#[test]
fn bad_layers_are_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::U8Range);
    let bone_file = write_tf(&dir.path().join("bone.toml"), &bone);
    let small = dir.path().join("small.pxo");
    support::import_volume(
        &support::marschner_lobb(40),
        &small,
        16,
        BrickEncoding::U8Range,
    );
    let corrupt = dir.path().join("corrupt.pxo");
    let mut bytes = std::fs::read(&db).unwrap();
    bytes.truncate(100);
    std::fs::write(&corrupt, &bytes).unwrap();
    let cfg = RenderConfig::default();
    let open = |l: Layer| {
        let t = std::time::Instant::now();
        let e = Renderer::with_layers(&db, &[l], &cfg, &AdapterRequest::from_env(None, 0))
            .err()
            .expect("refused");
        (format!("{e:#}"), t.elapsed())
    };
    for (l, want) in [
        (layer(&small, &bone_file), "layer[0].volume"),
        (layer(&corrupt, &bone_file), "layer[0].volume"),
        (
            layer(&db, &dir.path().join("none.toml")),
            "layer[0].transfer_function",
        ),
    ] {
        let (e, took) = open(l);
        println!("refused in {took:?}: {e}");
        assert!(e.contains(want), "{e}");
        assert!(took.as_secs_f64() < 1.0);
    }
    let (e, _) = open(layer(&small, &bone_file));
    assert!(e.contains("not the scene volume's"), "{e}");
}

/// View-dependent opacity on a light field display (G10 §4): eyes on
/// either side of the head, each seeing it through multi-centre views
/// (G10 Eq. 1, the rays the simulator resamples for that eye). The layer's
/// share of an eye's image (its mean opacity over the volume's alone, as a
/// fraction of the full layer's) is that of the layer at the fixed opacity
/// the smoothstep gives the eye's direction to the head's centre.
#[test]
fn a_layers_share_at_two_eyes_follows_the_smoothstep() {
    let dir = tempfile::tempdir().unwrap();
    let Some(db) = support::colin27(dir.path(), BrickEncoding::U8Range) else {
        return;
    };
    let (skin, brain) = support::colin27_tfs();
    // The skin at a twentieth of its extinction: translucent, so that its
    // share of the image grows with its opacity instead of saturating.
    let skin_file = write_tf(&dir.path().join("skin.toml"), &skin.scaled_extinction(0.05));
    let placement = support::colin_placement();
    let cfg = RenderConfig::default();
    let v = ViewOpacity {
        axis: [-1.0, 0.0, 0.0],
        angles_deg: [40.0, 130.0],
    };
    let mut rows = Vec::new();
    for ex in [-0.5, 0.7] {
        let views = support::colin27_lightfield(&[ex], 80);
        let alpha = |layers: &[Layer]| {
            let (f, _) = render(&db, layers, &brain, &placement, &views, &cfg);
            support::mean_alpha(&f.images[0])
        };
        let with = |opacity: f64, view_opacity| Layer {
            opacity,
            view_opacity,
            transform: None,
            ..layer(&db, &skin_file)
        };
        // The eye's direction to the head's centre, and its factor.
        let d = glam::DVec3::new(-ex, 0.0, -1.5).normalize();
        let theta = d.dot(glam::DVec3::from(v.axis)).acos().to_degrees();
        let f = v.factor(theta);
        let base = alpha(&[]);
        let full = alpha(&[with(1.0, None)]);
        let fixed = alpha(&[with(f, None)]);
        let seen = alpha(&[with(1.0, Some(v))]);
        let share = |a: f64| (a - base) / (full - base);
        println!(
            "eye at x = {ex}: {theta:.1}° to the axis, smoothstep {f:.3}; the layer's share {:.3} (at that fixed opacity {:.3}); mean opacity {base:.3} without it, {full:.3} at full",
            share(seen),
            share(fixed)
        );
        assert!(full - base > 0.02, "the skin adds opacity");
        rows.push((f, share(seen), share(fixed)));
    }
    for &(_, seen, fixed) in &rows {
        assert!((seen - fixed).abs() < 0.1, "{seen:.3} against {fixed:.3}");
    }
    assert!(
        rows[0].1 > rows[1].1 + 0.3,
        "the eyes see the layer differently"
    );
}

/// `volume` as a layer through `tf`, placed by a scale, a turn about z
/// (degrees) and a translation.
fn placed(volume: &Path, tf: &Path, scale: f64, turn: f64, t: [f64; 3]) -> Layer {
    let (s, c) = turn.to_radians().sin_cos();
    Layer {
        transform: Some(LayerTransform::Matrix(vec![
            [scale * c, -scale * s, 0.0, t[0]],
            [scale * s, scale * c, 0.0, t[1]],
            [0.0, 0.0, scale, t[2]],
        ])),
        ..layer(volume, tf)
    }
}

/// Numerical stability with layers: a constant volume, layers of huge
/// (1e6) and tiny (1e-9) extinction, a delta-like function, NaN voxels (no
/// data) in a layer, a view opacity with equal angles, and placed layers
/// turned, shrunk to a speck and blown up past the volume — every pixel
/// finite, in [0, 1], and a tiny layer changes the volume's image by no
/// more than its extinction can.
#[test]
fn extreme_layers_stay_finite() {
    let dir = tempfile::tempdir().unwrap();
    let n = 32;
    let constant = Volume::from_fn([n; 3], [1.0; 3], VoxelType::F32, |_, _, _| 100.0);
    let holes = Volume::from_fn([n; 3], [1.0; 3], VoxelType::F32, |i, j, k| {
        if (i + j + k) % 7 == 0 {
            f32::NAN
        } else {
            (i * 8) as f32
        }
    });
    let a = dir.path().join("constant.pxo");
    let b = dir.path().join("holes.pxo");
    support::import_volume(&constant, &a, 16, BrickEncoding::F32);
    support::import_volume(&holes, &b, 16, BrickEncoding::F32);
    let flat = |tau: f64| {
        TransferFunction::from_points(vec![
            ControlPoint::new(0.0, [0.2, 0.6, 1.0], tau),
            ControlPoint::new(300.0, [1.0, 0.6, 0.2], tau),
        ])
        .unwrap()
    };
    let delta = TransferFunction::from_points(vec![
        ControlPoint::new(99.999, [1.0, 1.0, 1.0], 0.0),
        ControlPoint::new(100.0, [1.0, 1.0, 1.0], 1e4),
        ControlPoint::new(100.001, [1.0, 1.0, 1.0], 0.0),
    ])
    .unwrap();
    let huge = write_tf(&dir.path().join("huge.toml"), &flat(1e6));
    let tiny = write_tf(&dir.path().join("tiny.toml"), &flat(1e-9));
    let delta_file = write_tf(&dir.path().join("delta.toml"), &delta);
    let placement = Placement {
        center: [0.0; 3],
        rotation_deg: [20.0, 35.0, 0.0],
        size: 0.2,
    };
    let view = View::window([48, 48], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let cfg = RenderConfig::default();
    let base = flat(0.01);
    let (alone, _) = render(&a, &[], &base, &placement, &[view], &cfg);
    let cases = [
        ("huge", vec![layer(&a, &huge)]),
        ("tiny", vec![layer(&a, &tiny)]),
        ("delta", vec![layer(&a, &delta_file)]),
        ("holes", vec![layer(&b, &huge), layer(&b, &tiny)]),
        (
            "equal angles",
            vec![Layer {
                view_opacity: Some(ViewOpacity {
                    axis: [0.0, 0.0, 1.0],
                    angles_deg: [90.0, 90.0],
                }),
                ..layer(&a, &huge)
            }],
        ),
        // Placed layers: turned 30° and halved, a speck (1/1000 of its
        // size), and one blown up so that the volume is inside one voxel.
        (
            "placed, turned",
            vec![placed(&b, &huge, 0.5, 30.0, [8.0, 2.0, 5.0])],
        ),
        (
            "placed, a speck",
            vec![placed(&b, &huge, 1e-3, 0.0, [16.0; 3])],
        ),
        (
            "placed, huge",
            vec![placed(&b, &huge, 1e3, 10.0, [-16000.0; 3])],
        ),
    ];
    for (name, layers) in cases {
        let (f, _) = render(&a, &layers, &base, &placement, &[view], &cfg);
        let img = &f.images[0];
        support::assert_valid(name, img);
        let (rmse, max) = support::error(
            img,
            &alone.images[0]
                .iter()
                .map(|p| p.map(f64::from))
                .collect::<Vec<_>>(),
        );
        println!("{name}: finite, in [0, 1]; against the volume alone RMSE {rmse:.2e}, max {max:.2e}, mean opacity {:.3}", support::mean_alpha(img));
        if name == "tiny" {
            assert!(max < 1e-6, "a 1e-9 layer: {max:.2e}");
        }
        // Smaller than a voxel, the speck reaches no voxel centre: outside
        // its box a placed layer is no medium.
        if name == "placed, a speck" {
            assert!(max < 1e-6, "a speck: {max:.2e}");
        }
        if name == "huge" || name == "equal angles" {
            assert!(support::mean_alpha(img) > support::mean_alpha(&alone.images[0]));
        }
    }
}
