//! Isosurface mode (`mode = "iso"`, G08 §5.3, B10): hits against surfaces
//! known in closed form, and the loader's emptiness test as the isovalue
//! range test (G08 §4).

mod support;

use parallax_backend::data;
use parallax_backend::data::synth::{synth_value, SynthKind};
use parallax_backend::render::Renderer;
use parallax_backend::store::{self, BrickEncoding, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Interpolation, Mode, RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;

fn iso_config(isovalue: f64) -> RenderConfig {
    RenderConfig {
        mode: Mode::Iso,
        isovalue: Some(isovalue),
        shading: Shading::None,
        step_factor: 0.5,
        accuracy: 0.01,
        visibility_feedback: false,
        interpolation: Interpolation::Exact,
        ..RenderConfig::default()
    }
}

fn grey() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.8, 0.8, 0.8], 0.0),
        ControlPoint::new(1.0, [0.8, 0.8, 0.8], 0.0),
    ])
    .unwrap()
}

/// The n³ shells volume (f32) and its database in `dir` (bricks of 16,
/// full precision).
fn shells(n: usize, dir: &Path) -> (Volume, std::path::PathBuf) {
    let vol = Volume::from_fn([n; 3], [1.0; 3], VoxelType::F32, |i, j, k| {
        synth_value(SynthKind::Shells, i, j, k, n) as f32
    });
    let db = dir.join("shells.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &db,
        "shells",
        &ImportOptions {
            brick: 16,
            encoding: BrickEncoding::F32,
            ..Default::default()
        },
    )
    .unwrap();
    (vol, db)
}

/// The shells volume's outermost surface at value v: the second shell
/// (radius 0.4, peak 0.75, Gaussian width 0.04 on [−1, 1]) reaches v at
/// r = 0.4 + 0.04·√(2 ln(0.75/v)) (shells 3 and 4 peak below v).
fn shell_radius(v: f64) -> f64 {
    0.4 + 0.04 * (2.0 * (0.75 / v).ln()).sqrt()
}

/// The silhouette of the shells' isosurface, seen from far away, has the
/// analytic radius: the pixel count of hits gives the radius to a small
/// fraction of a voxel.
#[test]
fn shell_hits_match_the_analytic_radius() {
    let n = 96;
    let dir = tempfile::tempdir().unwrap();
    let (vol, db) = shells(n, dir.path());
    // 0.2 m across the volume, seen from 20 m: nearly parallel rays.
    let size = 0.2;
    let placement = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [0.0, 0.0, 0.0],
        size,
    };
    let (w, px) = (0.12, 200u32);
    let view = View::window([px, px], [w, w], [0.0, 0.0, 20.0]);
    for v in [0.6, 0.7] {
        let cfg = iso_config(v);
        let mut r = Renderer::new(&db, &cfg).unwrap();
        r.set_transfer_function(1, &grey()).unwrap();
        let f = r.converge(&placement, &[view], &cfg, 30).unwrap();
        let img = &f.images[0];
        support::assert_valid("iso", img);
        let hits = img.iter().filter(|p| p[3] > 0.5).count();
        // Every pixel is a hit (opaque, the surface colour) or a miss.
        for p in img {
            assert!(
                p[3] == 0.0 || (p[3] == 1.0 && (p[0] - 0.8).abs() < 1e-6),
                "{p:?}"
            );
        }
        let pixel = w / px as f64;
        let rho = (hits as f64 * pixel * pixel / std::f64::consts::PI).sqrt();
        // Tangent rays from the eye at distance D: ρ = R·D/√(D² − R²).
        let metres_per_voxel = size / n as f64;
        let r_true = shell_radius(v) * n as f64 / 2.0 * metres_per_voxel;
        let d = 20.0;
        let rho_true = r_true * d / (d * d - r_true * r_true).sqrt();
        let err_voxels = (rho - rho_true).abs() / metres_per_voxel;
        eprintln!(
            "isovalue {v}: silhouette radius {:.3} voxels, analytic {:.3}: {err_voxels:.3} voxels off ({hits} hits)",
            rho / metres_per_voxel,
            rho_true / metres_per_voxel
        );
        // The sampled volume's trilinear field has its surface slightly
        // inside the analytic one where the Gaussian peak is sharp (σ = 1.9
        // voxels here): 0.04 voxels at 0.6, 0.12 at 0.7, near the peak 0.75.
        assert!(err_voxels < 0.15, "{err_voxels} voxels");
        // Against the trilinear field itself, marched on the CPU in steps of
        // 1/50 voxel: the same pixels hit, but for rays that graze it.
        let ext = vol.info.extent();
        let cpu_hit = |x: u32, y: u32| -> bool {
            let (o, d) = view.ray(x, y);
            let (vo, vd) = placement.ray_to_volume(ext, o, d);
            let Some((t0, t1)) =
                parallax_backend::reference::clip_to_box(vo, vd, glam::DVec3::from(ext))
            else {
                return false;
            };
            let mut prev = vol.sample((vo + vd * t0).into()) - v;
            let mut t = t0;
            while t < t1 {
                t = (t + 0.02).min(t1);
                let s = vol.sample((vo + vd * t).into()) - v;
                if (s < 0.0) != (prev < 0.0) {
                    return true;
                }
                prev = s;
            }
            false
        };
        let differ = (0..px * px)
            .filter(|&p| (img[p as usize][3] > 0.5) != cpu_hit(p % px, p / px))
            .count();
        eprintln!("  {differ} of {hits} pixels differ from the CPU-marched field");
        assert!(differ * 200 < hits, "{differ} pixels differ");
    }
}

/// On Colin27, the isosurface mode loads only bricks whose range holds the
/// isovalue, far fewer than the transfer function's DVR needs.
#[test]
fn colin27_cut_holds_only_bricks_straddling_the_isovalue() {
    let path = Path::new("/usr/share/mricron/templates/ch2.nii.gz");
    if !path.exists() {
        eprintln!(
            "SKIPPED: {} is not installed (apt: mricron-data)",
            path.display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("colin27.pxo");
    store::import(
        data::open(path, None).unwrap().as_mut(),
        &db,
        "colin27",
        &ImportOptions {
            brick: 16,
            ..Default::default()
        },
    )
    .unwrap();
    let tf = TransferFunction::load(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/tf/colin27-skin.toml"),
    )
    .unwrap();
    let placement = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [-90.0, 180.0, 0.0],
        size: 0.25,
    };
    let view = View::window([96, 72], [0.4, 0.3], [0.0, 0.0, 0.8]);
    let iso = 150.0;
    let mut cfg = iso_config(iso);
    cfg.shading = Shading::Phong;
    cfg.accuracy = 1.0;
    let mut r = Renderer::new(&db, &cfg).unwrap();
    r.set_transfer_function(1, &tf).unwrap();
    let f = r.converge(&placement, &[view], &cfg, 40).unwrap();
    assert!(f.stats.adequate);
    let hits = f.images[0].iter().filter(|p| p[3] == 1.0).count();
    assert!(hits > 500, "{hits} pixels show the surface");
    let resident = r.resident_bricks();
    assert!(!resident.is_empty());
    for k in &resident {
        let n = r.db().node(*k).unwrap();
        assert!(
            n.min as f64 <= iso && iso <= n.max as f64,
            "brick {k} [{}, {}] cannot hold the surface {iso}",
            n.min,
            n.max
        );
    }
    // The same view in DVR with the skin transfer function.
    let dvr = RenderConfig {
        mode: Mode::Dvr,
        isovalue: None,
        ..cfg.clone()
    };
    let mut d = Renderer::new(&db, &dvr).unwrap();
    d.set_transfer_function(1, &tf).unwrap();
    d.converge(&placement, &[view], &dvr, 40).unwrap();
    let dvr_bricks = d.resident_bricks().len();
    eprintln!(
        "colin27 isosurface {iso}: {} bricks resident, all straddling it; DVR: {dvr_bricks}",
        resident.len()
    );
    assert!(resident.len() < dvr_bricks);
}

/// Scene files: iso needs an isovalue; an isovalue needs iso.
#[test]
fn iso_scenes_are_checked() {
    let d = tempfile::tempdir().unwrap();
    let write = |name: &str, render: &str| {
        let p = d.path().join(name);
        std::fs::write(
            &p,
            format!("volume = \"v.pxo\"\ntransfer_function = \"tf.toml\"\n[placement]\ncenter = [0, 0, 0]\nsize = 0.2\n[render]\n{render}"),
        )
        .unwrap();
        p
    };
    use parallax_common::config::Scene;
    let e = Scene::load(&write("a.toml", "mode = \"iso\"\n")).unwrap_err();
    assert!(format!("{e:#}").contains("a.toml: render.mode = \"iso\" needs render.isovalue"));
    let e = Scene::load(&write("b.toml", "isovalue = 3\n")).unwrap_err();
    assert!(format!("{e:#}").contains("b.toml: render.isovalue applies to mode = \"iso\""));
    let s = Scene::load(&write("c.toml", "mode = \"iso\"\nisovalue = 80\n")).unwrap();
    assert_eq!(s.render.isovalue, Some(80.0));
}

/// The prediction buffer (B10 §4) on the shells turning 1° per frame: a full
/// traversal every α frames equals the plain isosurface render bit for bit,
/// and the predicted frames in between differ from it in few pixels.
#[test]
fn the_prediction_buffer_follows_a_rotation() {
    let n = 64;
    let dir = tempfile::tempdir().unwrap();
    let (_, db) = shells(n, dir.path());
    let view = View::window([96, 72], [0.4, 0.3], [0.0, 0.0, 0.8]);
    let mut plain = iso_config(0.3);
    plain.accuracy = 1.0;
    plain.shading = Shading::Phong;
    let pb_cfg = RenderConfig {
        prediction: true,
        full_traversal_every: 5,
        ..plain.clone()
    };
    let at = |f: usize| Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [20.0, 30.0 + f as f64, 0.0],
        size: 0.2,
    };
    let mut a = Renderer::new(&db, &plain).unwrap();
    let mut b = Renderer::new(&db, &pb_cfg).unwrap();
    for r in [&mut a, &mut b] {
        r.set_transfer_function(1, &grey()).unwrap();
        r.converge(&at(0), &[view], &plain, 30).unwrap();
        r.sync_io = true;
    }
    let mut predicted = Vec::new();
    for f in 0..12 {
        let x = a.frame(f as u64, &at(f), &[view], &plain).unwrap();
        let y = b.frame(f as u64, &at(f), &[view], &pb_cfg).unwrap();
        let was_predicted = y.predicted;
        let (x, y) = (&x.images[0], &y.images[0]);
        if was_predicted {
            let differ = x
                .iter()
                .zip(y)
                .filter(|(p, q)| (0..4).any(|c| (p[c] - q[c]).abs() > 1.0 / 255.0))
                .count();
            eprintln!(
                "frame {f}: predicted, {differ} of {} pixels differ",
                x.len()
            );
            assert!(differ * 100 < x.len(), "frame {f}: {differ} pixels differ");
        } else {
            assert!(
                x == y,
                "frame {f}: a full traversal equals the plain render"
            );
        }
        predicted.push(was_predicted);
    }
    // Full traversal first (no prediction yet), then every 5th frame.
    let want: Vec<bool> = (0..12).map(|f| f % 5 != 0).collect();
    assert_eq!(predicted, want);
}
