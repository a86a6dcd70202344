//! Tool geometry over the views (G10 §5): the 3D cursor lands, in every
//! projector view of the 16-projector wall, on the pixel whose G10 Eq. 1
//! ray passes through it, so every eye sees it at the same place in
//! space; the tools' outlines are drawn where their shapes project.

mod support;

use glam::DVec3;
use parallax_backend::render::Renderer;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Display, RenderConfig};
use parallax_common::overlay::{project, Overlay};
use parallax_common::tf::{ControlPoint, TransferFunction};
use parallax_common::tools::{ClipPlane, Probe, Tool};
use std::path::Path;
use support::{configs, exact_config, import_volume, translucent};

fn placement() -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [0.0; 3],
        size: 0.4,
    }
}

/// A 32³ ball, in bricks of 8.
fn ball(dir: &Path) -> std::path::PathBuf {
    let vol = Volume::from_fn([32; 3], [1.0; 3], VoxelType::U8, |i, j, k| {
        let r = DVec3::new(i as f64 - 15.5, j as f64 - 15.5, k as f64 - 15.5).length();
        if r < 12.0 {
            200.0
        } else {
            0.0
        }
    });
    let db = dir.join("ball.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::U8Range);
    db
}

fn render(
    db: &Path,
    tf: &TransferFunction,
    tools: &[Tool],
    views: &[View],
    cfg: &RenderConfig,
) -> Vec<Vec<[f32; 4]>> {
    let mut r = Renderer::new(db, cfg).unwrap();
    r.set_transfer_function(1, tf).unwrap();
    r.set_tools(1, tools).unwrap();
    r.converge(&placement(), views, cfg, 10).unwrap().images
}

/// The centroid (pixel coordinates, centres at .5) of a view's pixels that
/// differ from `base`, and how many there are.
fn centroid(img: &[[f32; 4]], base: &[[f32; 4]], width: u32) -> (f64, f64, usize) {
    let (mut x, mut y, mut n) = (0.0, 0.0, 0usize);
    for (k, (p, q)) in img.iter().zip(base).enumerate() {
        if p != q {
            x += (k as u32 % width) as f64 + 0.5;
            y += (k as u32 / width) as f64 + 0.5;
            n += 1;
        }
    }
    (x / n.max(1) as f64, y / n.max(1) as f64, n)
}

/// The cursor's dot, drawn over the wall at points in front of, on and
/// behind the screen (in the volume and in the air beside it), lands in
/// every projector view that sees it within a pixel of where the
/// projector's Eq. 1 ray through the point leaves it: the shape every eye
/// sees is the point itself.
#[test]
fn the_cursor_lands_where_each_projectors_ray_predicts() {
    let dir = tempfile::tempdir().unwrap();
    let db = ball(dir.path());
    let display = Display::load(&configs().join("displays/wall16/display.toml")).unwrap();
    let views = display.views(1.0);
    assert_eq!(views.len(), 16);
    let tf = translucent();
    let plain_cfg = exact_config();
    let base = render(&db, &tf, &[], &views, &plain_cfg);
    let (mut worst, mut seen) = (0f64, 0);
    for cursor in [
        [0.0, 0.0, 0.0],
        [0.1, 0.05, 0.15],
        [-0.12, -0.04, -0.1],
        [0.5, 0.2, 0.3],
        [-0.4, 0.1, -0.5],
    ] {
        let cfg = RenderConfig {
            overlay: Overlay {
                show: true,
                cursor: Some(cursor),
                cursor_size: 0.0,
                labels: false,
                ..Default::default()
            },
            ..plain_cfg.clone()
        };
        let imgs = render(&db, &tf, &[], &views, &cfg);
        for (v, (img, b)) in views.iter().zip(imgs.iter().zip(&base)) {
            let [w, h] = v.resolution;
            let Some([px, py]) = project(v, DVec3::from(cursor)) else {
                continue;
            };
            // Views where the dot lies wholly inside.
            if px < 4.0 || py < 4.0 || px > w as f64 - 4.0 || py > h as f64 - 4.0 {
                continue;
            }
            let (cx, cy, n) = centroid(img, b, w);
            assert!(n >= 16, "cursor {cursor:?}, view {:?}: {n} pixels", v.eye);
            // The predicted pixel's ray passes through the cursor: the
            // inverse map, checked against View::ray at the pixel centre
            // nearest the dot's centre.
            let (i, j) = (cx.floor() as u32, cy.floor() as u32);
            let (o, d) = v.ray(i, j);
            let miss = (DVec3::from(cursor) - o).cross(d).length();
            let pixel = v.region[2] / w as f64 * (DVec3::from(cursor) - o).length()
                / (DVec3::from(v.observer).z - 0.0).abs().max(1e-9);
            let err = (cx - px).hypot(cy - py);
            worst = worst.max(err);
            seen += 1;
            assert!(err <= 1.0, "cursor {cursor:?}, view {:?}: dot at ({cx:.2}, {cy:.2}), ray predicts ({px:.2}, {py:.2})", v.eye);
            assert!(miss < 2.0 * pixel, "cursor {cursor:?}, view {:?}: pixel ({i}, {j})'s ray misses by {miss} m (pixel {pixel} m)", v.eye);
        }
    }
    eprintln!(
        "cursor dot against the Eq. 1 prediction over {seen} projector views: worst {worst:.3} px"
    );
    assert!(seen >= 40, "{seen}");
}

/// The tools' geometry: a probe's outline circles and a clip plane's
/// outline appear where they project, over rays that miss the volume and
/// tiles the culling drops (a transparent transfer function), and the
/// overlay off leaves the image bit for bit.
#[test]
fn tool_outlines_are_drawn_where_they_project() {
    let dir = tempfile::tempdir().unwrap();
    let db = ball(dir.path());
    let view = View::window([160, 120], [0.8, 0.6], [0.0, 0.0, 1.5]);
    let clear = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(255.0, [0.0; 3], 0.0),
    ])
    .unwrap();
    let probe = Probe::new([0.05, 0.02, 0.0], 0.1);
    let plane = ClipPlane {
        point: [0.0; 3],
        normal: [0.0, 0.0, 1.0],
        thickness: 0.0,
        context: [0.3, 0.7],
    };
    let tools = [Tool::Probe(probe), Tool::ClipPlane(plane)];
    let cfg = exact_config();
    let plain = render(&db, &clear, &tools, &[view], &cfg).remove(0);
    assert!(plain.iter().all(|p| p[3] == 0.0));
    let on = RenderConfig {
        overlay: Overlay {
            show: true,
            labels: false,
            ..Default::default()
        },
        ..cfg.clone()
    };
    let img = render(&db, &clear, &tools, &[view], &on).remove(0);
    let lit = |x: f64, y: f64| {
        // Any pixel within 1.5 px of (x, y).
        (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                let (i, j) = (
                    (x + dx as f64).floor() as i64,
                    (y + dy as f64).floor() as i64,
                );
                (0..160).contains(&i)
                    && (0..120).contains(&j)
                    && img[(j * 160 + i) as usize][3] > 0.3
            })
        })
    };
    // The probe's circle in the screen plane (its centre's depth): 64
    // points around it.
    let c = DVec3::from(probe.center);
    for k in 0..64 {
        let a = std::f64::consts::TAU * k as f64 / 64.0;
        let q = c + DVec3::new(a.cos(), a.sin(), 0.0) * probe.radius;
        let [x, y] = project(&view, q).unwrap();
        assert!(lit(x, y), "probe outline missing at ({x:.1}, {y:.1})");
    }
    // The clip plane's outline: the volume's box cut at z = 0, a square of
    // side 0.4 m; its corners.
    for q in [[-0.2, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.2, 0.2]] {
        let [x, y] = project(&view, DVec3::new(q[0], q[1], 0.0)).unwrap();
        assert!(lit(x, y), "clip plane corner missing at ({x:.1}, {y:.1})");
    }
    // Far from every shape nothing is drawn.
    let [x, y] = project(&view, DVec3::new(-0.35, 0.25, 0.0)).unwrap();
    assert!(!lit(x, y));
    let drawn = img.iter().filter(|p| p[3] > 0.0).count();
    eprintln!("tool outlines: {drawn} of {} pixels drawn", img.len());
    assert!(drawn > 300 && drawn < 6000, "{drawn}");
}

/// Depth combination: the cursor inside an opaque ball (behind its front
/// surface) is hidden, in front of it or beside it shown; without depth
/// combination it shines through. With refraction it is refused.
#[test]
fn with_depth_combination_a_cursor_behind_opaque_matter_is_hidden() {
    let dir = tempfile::tempdir().unwrap();
    let db = ball(dir.path());
    let view = View::window([120, 90], [0.6, 0.45], [0.0, 0.0, 1.5]);
    let opaque = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(100.0, [0.0; 3], 0.0),
        ControlPoint::new(150.0, [0.8, 0.5, 0.4], 20.0),
        ControlPoint::new(255.0, [0.8, 0.5, 0.4], 20.0),
    ])
    .unwrap();
    let cfg = exact_config();
    let base = render(&db, &opaque, &[], &[view], &cfg).remove(0);
    // The ball (radius 12 voxels of 32: 0.15 m) covers the centre.
    assert!(base[45 * 120 + 60][3] > 0.99);
    let dot = |cursor: [f64; 3], depth: bool| {
        let cfg = RenderConfig {
            overlay: Overlay {
                show: true,
                cursor: Some(cursor),
                cursor_size: 0.0,
                labels: false,
                depth,
                ..Default::default()
            },
            ..cfg.clone()
        };
        let img = render(&db, &opaque, &[], &[view], &cfg).remove(0);
        centroid(&img, &base, 120).2
    };
    let inside = [0.02, 0.01, 0.0];
    let front = [0.02, 0.01, 0.2];
    let beside = [0.25, 0.1, 0.0];
    let counts = [
        dot(inside, false),
        dot(inside, true),
        dot(front, true),
        dot(beside, true),
    ];
    eprintln!(
        "cursor pixels: inside the ball {} (over) / {} (depth), in front {}, beside {}",
        counts[0], counts[1], counts[2], counts[3]
    );
    assert!(counts[0] >= 16, "{counts:?}");
    assert_eq!(counts[1], 0, "{counts:?}");
    assert!(counts[2] >= 16 && counts[3] >= 16, "{counts:?}");

    let refracting = RenderConfig {
        refraction: true,
        overlay: Overlay {
            show: true,
            cursor: Some(inside),
            depth: true,
            ..Default::default()
        },
        ..cfg.clone()
    };
    let mut r = Renderer::new(&db, &refracting).unwrap();
    r.set_transfer_function(1, &opaque).unwrap();
    let e = r
        .frame(0, &placement(), &[view], &refracting)
        .err()
        .expect("depth combination with refraction is refused")
        .to_string();
    assert!(
        e.contains("render.overlay.depth") && e.contains("refraction"),
        "{e}"
    );
}
