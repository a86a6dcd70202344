//! Multilevel shading (G10 §3, Fig. 5): the unsharp-masked gradient and
//! exaggerated shading, as enhancers on the octree's coarser levels,
//! against an analytic volume whose every level's gradient has a closed
//! form, and against plain shading at zero strength.

mod support;

use glam::DVec3;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, TransferFunction};
use parallax_common::tools::{ExaggeratedShading, Tool, UnsharpGradient};
use std::f64::consts::PI;
use std::path::Path;
use support::{exact_config, import_volume, translucent};

const N: usize = 32;
/// s = S0 + A·sin(k·x) + B·y, constant along z (voxel units, spacing 1).
const S0: f64 = 100.0;
const A: f64 = 40.0;
const B: f64 = 20.0;
/// Eight voxels a period: the parent (voxel 2) keeps it attenuated, the
/// grandparent (voxel 4) samples it at Nyquist, where its central
/// difference vanishes.
const K: f64 = 2.0 * PI / 8.0;

/// The converged image of `view` with `tools`, the volume at [`placement`].
fn render(
    db: &Path,
    tf: &TransferFunction,
    tools: &[Tool],
    view: &View,
    cfg: &RenderConfig,
) -> Vec<[f32; 4]> {
    support::render_tools(db, tf, tools, &placement(), view, cfg)
}

fn placement() -> Placement {
    Placement {
        center: [0.0; 3],
        rotation_deg: [0.0; 3],
        size: 0.3,
    }
}

/// Nearly parallel rays down the z axis over the middle of the volume.
fn view() -> View {
    View::window([48, 48], [0.24, 0.24], [0.0, 0.0, 4.0])
}

/// The ripples on a ramp, in full-precision bricks of 8: levels of voxel
/// 1, 2 and 4.
fn ripples(dir: &Path) -> std::path::PathBuf {
    let vol = Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |i, j, _| {
        let (x, y) = (i as f64 + 0.5, j as f64 + 0.5);
        (S0 + A * (K * x).sin() + B * y) as f32
    });
    let db = dir.join("ripples.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    db
}

/// White and so dense that a ray is opaque within a tenth of a voxel: a
/// pixel shows its ray's first samples.
fn opaque_white() -> TransferFunction {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [1.0, 1.0, 1.0], 80.0),
        ControlPoint::new(1000.0, [1.0, 1.0, 1.0], 80.0),
    ])
    .unwrap()
}

/// ∂s/∂x of the level whose voxel is `h` (1, 2, 4) at x, as the kernel
/// computes it: central differences of ±h on the trilinear interpolant of
/// that level's voxels, which are box averages of the finer ones. A box of
/// width w turns A·sin(k·x) into A·sin(k·x)·∏cos(k·w/2) (one halving a
/// level), the central difference of a sampled sine is exact up to the
/// factor sin(k·h)/h, and between voxel centres the interpolant's
/// difference is the linear interpolation of the centres' cosines.
fn dsdx(level_voxel: f64, x: f64) -> f64 {
    let h = level_voxel;
    // Box averages down to this level: voxel 2 averages pairs (cos(k/2)),
    // voxel 4 pairs of those (cos(k)).
    let mut amp = A;
    let mut w = 1.0;
    while w < h {
        amp *= (K * w / 2.0).cos();
        w *= 2.0;
    }
    let c0 = ((x - h / 2.0) / h).floor() * h + h / 2.0;
    let t = (x - c0) / h;
    let cosine = (1.0 - t) * (K * c0).cos() + t * (K * (c0 + h)).cos();
    amp * (K * h).sin() / h * cosine
}

/// Where pixel (i, j)'s ray enters the volume's top face (volume space).
fn entry(view: &View, i: u32, j: u32) -> DVec3 {
    let (o, d) = view.ray(i, j);
    let (vo, vd) = placement().ray_to_volume([N as f64; 3], o, d);
    vo + vd * ((N as f64 - vo.z) / vd.z)
}

/// The pixels whose rays enter well inside, where every level's central
/// difference reads voxels of the volume (not its clamped edge).
fn inner(view: &View) -> impl Iterator<Item = (u32, u32, DVec3)> + '_ {
    (0..view.resolution[1]).flat_map(move |j| {
        (0..view.resolution[0]).filter_map(move |i| {
            let p = entry(view, i, j);
            (p.x > 6.0 && p.x < 26.0 && p.y > 6.0 && p.y < 26.0).then_some((i, j, p))
        })
    })
}

/// With zero strength, unsharp masking and exaggerated shading leave
/// plain shading bit for bit (Phong and unshaded, DVR: the renderer leaves
/// them out); at a millionth of full strength the kernel that runs them
/// moves no pixel by more than 1e-5 (the knob is continuous at 0); at full
/// strength they change the image.
#[test]
fn zero_strength_is_plain_shading_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let db = ripples(dir.path());
    let view = View::window([40, 30], [0.4, 0.3], [0.01, 0.005, 0.8]);
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(300.0, [0.9, 0.6, 0.3], 0.05),
        ControlPoint::new(800.0, [0.3, 0.6, 1.0], 0.3),
    ])
    .unwrap();
    let unsharp = |strength: f64| {
        Tool::UnsharpGradient(UnsharpGradient {
            strength,
            ..Default::default()
        })
    };
    let exaggerated = |strength: f64| {
        Tool::ExaggeratedShading(ExaggeratedShading {
            strength,
            ..Default::default()
        })
    };
    for shading in [Shading::Phong, Shading::None] {
        let cfg = RenderConfig {
            shading,
            ..exact_config()
        };
        let plain = render(&db, &tf, &[], &view, &cfg);
        for tools in [
            vec![unsharp(0.0)],
            vec![exaggerated(0.0)],
            vec![unsharp(0.0), exaggerated(0.0)],
        ] {
            let img = render(&db, &tf, &tools, &view, &cfg);
            assert!(
                img == plain,
                "{shading:?} {tools:?} differs from plain shading"
            );
        }
        for tools in [
            vec![unsharp(1e-6)],
            vec![exaggerated(1e-6)],
            vec![unsharp(1e-6), exaggerated(1e-6)],
        ] {
            let img = render(&db, &tf, &tools, &view, &cfg);
            let worst = img
                .iter()
                .zip(&plain)
                .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
                .fold(0f32, f32::max);
            assert!(worst < 1e-5, "{shading:?} {tools:?}: {worst}");
        }
        // At strength, exaggerated shading changes the image shaded or not;
        // unsharp masking changes only a shaded one.
        let changed = |tools: &[Tool]| {
            let img = render(&db, &tf, tools, &view, &cfg);
            img.iter().zip(&plain).filter(|(a, b)| a != b).count()
        };
        let (u, e) = (changed(&[unsharp(1.0)]), changed(&[exaggerated(1.0)]));
        eprintln!("{shading:?}: pixels changed by unsharp masking {u}, by exaggerated shading {e} of 1200");
        assert!(e > 600, "{e}");
        if shading == Shading::Phong {
            assert!(u > 600, "{u}");
        } else {
            assert_eq!(u, 0);
        }
    }
}

/// G10 Fig. 5 (right): the unsharp-masked gradient g + λ·(g − g_c) of the
/// ripples, shown by the gradient diagnostic, against the closed form of
/// each level's gradient: the x component grows by λ·(g_x − g_{c,x}), the
/// ramp's y component, the same at every level, stays.
#[test]
fn the_unsharp_masked_gradient_matches_the_analytic_volume() {
    let dir = tempfile::tempdir().unwrap();
    let db = ripples(dir.path());
    let view = view();
    let cfg = exact_config();
    let tf = opaque_white();
    let mut angle_at = Vec::new();
    for (lambda, level) in [(0.0, 1), (1.0, 1), (2.5, 1), (1.0, 2)] {
        let tools = [
            Tool::UnsharpGradient(UnsharpGradient {
                strength: lambda,
                level,
            }),
            Tool::GradientDirection(Default::default()),
        ];
        let img = render(&db, &tf, &tools, &view, &cfg);
        let (mut sum, mut worst, mut count) = (0.0, 0f64, 0);
        let mut mean_angle = 0.0;
        for (i, j, p) in inner(&view) {
            let px = img[(j * view.resolution[0] + i) as usize];
            assert_eq!(px[3], 1.0, "({i}, {j}) is not opaque");
            let got = DVec3::new(px[0] as f64, px[1] as f64, px[2] as f64) * 2.0 - DVec3::ONE;
            let g = dsdx(1.0, p.x);
            let gc = dsdx(if level == 1 { 2.0 } else { 4.0 }, p.x);
            let want = DVec3::new(g + lambda * (g - gc), B, 0.0);
            let err = got.angle_between(want).to_degrees();
            sum += err;
            worst = worst.max(err);
            count += 1;
            mean_angle += want.y.atan2(want.x.abs()).to_degrees();
        }
        let mean = sum / count as f64;
        eprintln!(
            "λ = {lambda}, level {level}: masked gradient against the closed form over {count} rays: mean {mean:.3}°, worst {worst:.3}°"
        );
        assert!(count > 600, "{count}");
        assert!(mean < 0.1, "mean {mean}°");
        assert!(worst < 0.5, "worst {worst}°");
        angle_at.push(mean_angle / count as f64);
    }
    // Masking turns the normals measurably towards the ripples' slopes.
    assert!(angle_at[0] - angle_at[1] > 3.0, "{angle_at:?}");
    assert!(angle_at[1] - angle_at[2] > 3.0, "{angle_at:?}");
}

/// Exaggerated shading (Rusinkiewicz et al. 2006) of the ripples lit from
/// the side: each pixel's shade against the closed form from the three
/// levels' normals.
#[test]
fn exaggerated_shading_matches_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let db = ripples(dir.path());
    let view = view();
    let cfg = RenderConfig {
        shading: Shading::Phong,
        ..exact_config()
    };
    let tf = opaque_white();
    let tool = ExaggeratedShading {
        strength: 1.0,
        contrast: 3.0,
        light: [0.6, -0.3, 1.0],
        weights: [0.4, 0.2, 0.4],
    };
    let img = render(&db, &tf, &[Tool::ExaggeratedShading(tool)], &view, &cfg);
    let l = DVec3::from(tool.light).normalize();
    let normal = |h: f64, x: f64| -DVec3::new(dsdx(h, x), B, 0.0).normalize();
    let tangent = |n: DVec3| {
        let t = l - l.dot(n) * n;
        if t.length() > 1e-6 {
            t.normalize()
        } else {
            DVec3::ZERO
        }
    };
    let k = tool.weights.map(|w| w / tool.weights.iter().sum::<f64>());
    let (mut sum, mut worst, mut count) = (0.0, 0f64, 0);
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for (i, j, p) in inner(&view) {
        let (n0, n1, n2) = (normal(1.0, p.x), normal(2.0, p.x), normal(4.0, p.x));
        let a = tool.contrast;
        let e = 0.5
            + 0.5
                * (k[0] * (a * n0.dot(tangent(n1))).clamp(-1.0, 1.0)
                    + k[1] * (a * n1.dot(tangent(n2))).clamp(-1.0, 1.0)
                    + k[2] * n2.dot(l).clamp(-1.0, 1.0));
        // The kernel's material: ambient 0.35, diffuse 0.65.
        let want = 0.35 + 0.65 * e;
        let px = img[(j * view.resolution[0] + i) as usize];
        let got = px[0] as f64;
        let err = (got - want).abs();
        sum += err;
        worst = worst.max(err);
        count += 1;
        lo = lo.min(got);
        hi = hi.max(got);
    }
    let mean = sum / count as f64;
    eprintln!(
        "exaggerated shading against the closed form over {count} rays: mean |Δ| {mean:.4}, worst {worst:.4} (shades {lo:.3} to {hi:.3})"
    );
    assert!(count > 600);
    assert!(mean < 0.002, "mean {mean}");
    assert!(worst < 0.01, "worst {worst}");
    assert!(hi - lo > 0.2, "the ripples barely show: {lo} to {hi}");
}

/// Degenerate inputs stay finite: a constant volume (no gradient at any
/// level), the strongest masking and contrast, the light along the view.
#[test]
fn multilevel_shading_of_a_constant_volume_stays_finite() {
    let dir = tempfile::tempdir().unwrap();
    let vol = Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |_, _, _| 150.0);
    let db = dir.path().join("constant.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    let cfg = RenderConfig {
        shading: Shading::Phong,
        ..exact_config()
    };
    let tools = [
        Tool::UnsharpGradient(UnsharpGradient {
            strength: 10.0,
            level: 2,
        }),
        Tool::ExaggeratedShading(ExaggeratedShading {
            strength: 1.0,
            contrast: 1000.0,
            light: [0.0, 0.0, 1.0],
            weights: [1.0, 0.0, 0.0],
        }),
    ];
    let img = render(&db, &translucent(), &tools, &view(), &cfg);
    assert!(img.iter().any(|p| p[3] > 0.1));
}
