//! Looking Glass quilts: tile order (view 0 bottom-left, left to right then
//! bottom to top), the `_qs{cols}x{rows}a{aspect}` file name, the off-axis
//! cameras (shared focal plane, leftmost camera at negative x), and one small
//! rendered quilt whose parallax goes the right way.

use parallax_backend::data::{synth_value, SynthKind};
use parallax_backend::quilt::{
    assemble, format_aspect, quilt_file_name, quilt_path, quilt_views, tile_aspect,
    DEFAULT_CONE_DEG,
};
use parallax_backend::render::Renderer;
use parallax_backend::store::{self, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Interpolation, RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;

/// A constant, distinct colour per view.
fn colour(k: usize) -> [f32; 4] {
    [k as f32 / 100.0, 1.0 - k as f32 / 100.0, 0.5, 1.0]
}

#[test]
fn tiles_run_left_to_right_from_the_bottom_left() {
    let (cols, rows) = (4u32, 3u32);
    let tile = [5u32, 3u32];
    let n = (cols * rows) as usize;
    let images: Vec<Vec<[f32; 4]>> = (0..n).map(|k| vec![colour(k); 15]).collect();
    let q = assemble(cols, rows, tile, &images).unwrap();
    let qw = (cols * tile[0]) as usize;
    let qh = (rows * tile[1]) as usize;
    assert_eq!(q.len(), qw * qh);
    let at = |x: usize, y: usize| q[y * qw + x];
    // Corners of the quilt image (row 0 at the top).
    assert_eq!(at(0, qh - 1), colour(0), "bottom-left = view 0");
    assert_eq!(
        at(qw - 1, qh - 1),
        colour(cols as usize - 1),
        "bottom-right = view cols−1"
    );
    assert_eq!(
        at(0, 0),
        colour(n - cols as usize),
        "top-left = first view of the top row"
    );
    assert_eq!(at(qw - 1, 0), colour(n - 1), "top-right = last view");
    // Every pixel.
    for y in 0..qh {
        for x in 0..qw {
            let col = x / tile[0] as usize;
            let row_from_bottom = rows as usize - 1 - y / tile[1] as usize;
            assert_eq!(
                at(x, y),
                colour(row_from_bottom * cols as usize + col),
                "({x}, {y})"
            );
        }
    }
    // Pixels inside a tile keep their place (row 0 of a view at the tile's top).
    let mut images = images;
    images[0][0] = [9.0; 4]; // view 0, top-left pixel
    images[0][14] = [8.0; 4]; // view 0, bottom-right pixel
    let q = assemble(cols, rows, tile, &images).unwrap();
    assert_eq!(q[(qh - tile[1] as usize) * qw], [9.0; 4]);
    assert_eq!(q[(qh - 1) * qw + tile[0] as usize - 1], [8.0; 4]);
    // Wrong counts and sizes are refused, not mis-tiled.
    assert!(assemble(cols, rows, tile, &images[..n - 1]).is_err());
    let mut bad = images.clone();
    bad[3].pop();
    let e = format!("{:#}", assemble(cols, rows, tile, &bad).unwrap_err());
    assert!(e.contains("view 3"), "{e}");
    eprintln!("4×3 quilt of 5×3 tiles: every pixel in its tile; wrong sizes refused ({e})");
}

#[test]
fn file_names_carry_layout_and_aspect() {
    assert_eq!(quilt_file_name("scene", 8, 6, 0.75), "scene_qs8x6a0.75.png");
    assert_eq!(quilt_file_name("scene", 5, 9, 1.6), "scene_qs5x9a1.6.png");
    assert_eq!(
        quilt_file_name("s", 8, 6, tile_aspect([420, 560])),
        "s_qs8x6a0.75.png"
    );
    assert_eq!(format_aspect(tile_aspect([512, 288])), "1.78");
    assert_eq!(format_aspect(1.0), "1");
    assert_eq!(format_aspect(0.5), "0.5");
    assert_eq!(format_aspect(2.0 / 3.0), "0.67");
    assert_eq!(
        quilt_path(Path::new("out/scene.png"), 8, 6, 0.75),
        Path::new("out/scene_qs8x6a0.75.png")
    );
    assert_eq!(
        quilt_path(Path::new("out/scene"), 8, 6, 0.75),
        Path::new("out/scene_qs8x6a0.75.png")
    );
}

#[test]
fn cameras_are_off_axis_on_a_line() {
    let screen = [0.3, 0.4];
    let d = 1.2;
    let (cols, rows) = (8u32, 6u32);
    let tile = [42u32, 56u32];
    let views = quilt_views(screen, d, DEFAULT_CONE_DEG, cols, rows, tile);
    let n = views.len();
    assert_eq!(n, 48);
    let half = DEFAULT_CONE_DEG.to_radians() / 2.0;
    for (k, v) in views.iter().enumerate() {
        let want = d * (-half + k as f64 * 2.0 * half / (n - 1) as f64).tan();
        assert!((v.eye[0] - want).abs() < 1e-12, "view {k}: x {}", v.eye[0]);
        assert_eq!(v.eye[1], 0.0);
        assert_eq!(v.eye[2], d);
        assert_eq!(v.observer, v.eye);
        assert_eq!(v.eta, 0.0);
        assert_eq!(v.resolution, tile);
        // Every camera frames the same focal-plane rectangle.
        assert_eq!(v.region, [-0.15, -0.2, 0.3, 0.4]);
    }
    assert!(views[0].eye[0] < 0.0, "the leftmost camera is view 0");
    assert!(views.windows(2).all(|w| w[1].eye[0] > w[0].eye[0]));
    assert!((views[0].eye[0] + views[n - 1].eye[0]).abs() < 1e-12);
    assert!(((views[0].eye[0] / d).atan() + half).abs() < 1e-12);

    // Zero disparity on the focal plane: pixel (i, j) of every view looks
    // at the same screen point. A point in front of it moves right to left
    // from the leftmost to the rightmost camera.
    let p = glam::DVec3::new(0.0, 0.0, 0.1);
    let mut last = f64::INFINITY;
    for v in &views {
        let (o, dir) = v.ray(10, 20);
        let q = o + dir * (-o.z / dir.z);
        assert!((q - v.screen_point(10, 20)).length() < 1e-12);
        let e = glam::DVec3::from(v.eye);
        let hit = e + (p - e) * (e.z / (e.z - p.z));
        assert!(hit.x < last);
        last = hit.x;
    }
    let one = quilt_views(screen, d, DEFAULT_CONE_DEG, 1, 1, tile);
    assert_eq!(one[0].eye, [0.0, 0.0, d]);
}

/// A small rendered quilt of a volume in front of the focal plane: the
/// volume's image is furthest right in view 0 (the leftmost camera) and
/// moves left view after view, and the assembled quilt holds the views.
#[test]
fn rendered_quilt_has_parallax() {
    let n = 32;
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        (synth_value(SynthKind::Shells, i, j, k, n) * 255.0).round() as f32
    });
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("shells.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &db,
        "quilt test",
        &ImportOptions {
            brick: 16,
            ..Default::default()
        },
    )
    .unwrap();
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0, 0.0, 0.0], 0.0),
        ControlPoint::new(60.0, [0.2, 0.5, 1.0], 0.02),
        ControlPoint::new(255.0, [1.0, 0.8, 0.4], 0.4),
    ])
    .unwrap();
    let cfg = RenderConfig {
        shading: Shading::None,
        accuracy: 0.05,
        visibility_feedback: false,
        interpolation: Interpolation::Exact,
        ..RenderConfig::default()
    };
    let mut r = Renderer::new(&db, &cfg).unwrap();
    r.set_transfer_function(1, &tf).unwrap();
    // In front of the focal plane: crossed disparity.
    let placement = Placement {
        center: [0.0, 0.0, 0.15],
        rotation_deg: [0.0, 0.0, 0.0],
        size: 0.12,
    };
    let (cols, rows, tile) = (4u32, 2u32, [30u32, 40u32]);
    let views = quilt_views([0.3, 0.4], 1.0, DEFAULT_CONE_DEG, cols, rows, tile);
    let f = r.converge(&placement, &views, &cfg, 20).unwrap();
    let centroid = |img: &[[f32; 4]]| {
        let (mut s, mut sx) = (0.0, 0.0);
        for (p, px) in img.iter().enumerate() {
            let a = px[3] as f64;
            s += a;
            sx += a * (p % tile[0] as usize) as f64;
        }
        (sx / s, s / img.len() as f64)
    };
    let cx: Vec<f64> = f.images.iter().map(|im| centroid(im).0).collect();
    let alpha: Vec<f64> = f.images.iter().map(|im| centroid(im).1).collect();
    eprintln!("alpha centroid x per view (pixels): {cx:.2?}; mean alpha {alpha:.3?}");
    assert!(alpha.iter().all(|&a| a > 0.02));
    assert!(cx.windows(2).all(|w| w[1] < w[0]), "{cx:?}");
    // Expected shift of the centre (0, 0, 0.15) on the focal plane from the
    // extreme cameras: x_s = −E_x·0.15/(1 − 0.15).
    let px_per_m = tile[0] as f64 / 0.3;
    let want = |v: &View| 15.0 - v.eye[0] * 0.15 / 0.85 * px_per_m;
    for (k, v) in views.iter().enumerate() {
        assert!(
            (cx[k] - want(v)).abs() < 1.0,
            "view {k}: {} vs {}",
            cx[k],
            want(v)
        );
    }
    let q = assemble(cols, rows, tile, &f.images).unwrap();
    let qw = (cols * tile[0]) as usize;
    // view 0's top-left pixel → the bottom-left tile's top-left pixel
    assert_eq!(q[tile[1] as usize * qw], f.images[0][0]);
    let last = cols as usize * rows as usize - 1;
    assert_eq!(q[qw - tile[0] as usize], f.images[last][0]);
}
