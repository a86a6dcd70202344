//! Tools, enhancers and steppers (G10 §4–5) against the exact integral and
//! closed forms: the clip plane, MImDA, refraction, and the kernels
//! specialised for each combination.

mod support;

use glam::DVec3;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::render::Renderer;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Mode, RenderConfig, Shading};
use parallax_common::tf::{ControlPoint, TransferFunction};
use parallax_common::tools::{BandPicker, ClipPlane, Probe, Tool};
use std::path::Path;
use support::{exact_config, import_volume, marschner_lobb, mean_alpha, translucent};

use support::render_tools as render;

fn centred(rotation_deg: [f64; 3]) -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg,
        size: 0.3,
    }
}

/// The volume ML32 in full-precision bricks of 8.
fn ml32(dir: &Path) -> (Volume, std::path::PathBuf) {
    let vol = marschner_lobb(32);
    let db = dir.join("ml32.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    (vol, db)
}

fn head_on() -> View {
    View::window([40, 30], [0.4, 0.3], [0.01, 0.005, 0.8])
}

/// Concentric shells (period 4 voxels) about the exact centre of a 32³ box,
/// in full-precision bricks of 8.
fn shells(dir: &Path) -> std::path::PathBuf {
    let n = 32;
    let c = n as f64 / 2.0;
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        let r = DVec3::new(i as f64 + 0.5 - c, j as f64 + 0.5 - c, k as f64 + 0.5 - c).length();
        if r < 0.45 * n as f64 {
            (128.0 + 127.0 * (std::f64::consts::PI * r / 4.0).cos()).round() as f32
        } else {
            0.0
        }
    });
    let db = dir.join("shells.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    db
}

/// G10 §4 clip plane viewed head-on (context factor 0 on every ray) with no
/// band: exactly the integral of the volume with the cut-away half-space
/// removed — the plane is a segment boundary of every ray, so no segment
/// straddles it.
#[test]
fn a_clip_plane_head_on_removes_exactly_its_half_space() {
    let dir = tempfile::tempdir().unwrap();
    let (vol, db) = ml32(dir.path());
    let tf = translucent();
    let placement = centred([20.0, 35.0, 0.0]);
    let view = head_on();
    let cfg = exact_config();
    let planes = [
        ClipPlane {
            point: [0.01, 0.0, 0.02],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        },
        // Tilted 10°: still head-on (1 − cos 10° < f_l).
        ClipPlane {
            point: [0.0, -0.02, -0.01],
            normal: [0.0, 10f64.to_radians().sin(), 10f64.to_radians().cos()],
            thickness: 0.0,
            context: [0.3, 0.7],
        },
    ];
    let tol = Tolerance { abs: 1e-7 };
    let plain = render(&db, &tf, &[], &placement, &view, &cfg);
    let full = reference::render(&vol, &tf, &placement, &view, tol);
    let (e_plain, _) = support::error(&plain, &full);
    for plane in planes {
        let img = render(&db, &tf, &[Tool::ClipPlane(plane)], &placement, &view, &cfg);
        let want = reference::render_clipped(&vol, &tf, &placement, &view, tol, &[plane]);
        let (rmse, max) = support::error(&img, &want);
        let (cut, _) = support::error(&img, &full);
        eprintln!(
            "clip plane {:?}: RMSE {rmse:.2e} (max {max:.2e}) against the clipped integral; unclipped {e_plain:.2e}; the plane changes the image by {cut:.2e}",
            plane.normal
        );
        // As close to the clipped integral as the plain render is to the
        // whole one; the plane itself changes the image far more.
        assert!(rmse <= 1.5 * e_plain + 2e-5, "{rmse} vs {e_plain}");
        assert!(cut > 20.0 * rmse.max(1e-6), "{cut}");
        assert!(mean_alpha(&img) < mean_alpha(&plain));
    }
}

/// Spherically symmetric shells with a plane through the centre whose
/// normal turns from facing the viewer to lying across the view: the
/// context factor μ rises from 0 to 1, and the cut-away half returns with
/// it, monotonically.
#[test]
fn context_returns_monotonically_as_the_view_turns_parallel() {
    let dir = tempfile::tempdir().unwrap();
    let db = shells(dir.path());
    let tf = translucent();
    let placement = centred([0.0; 3]);
    // Nearly parallel rays, so that the part the plane keeps has the same
    // optical depth in all (up to sampling) whatever the plane's angle.
    let view = View::window([32, 32], [0.32, 0.32], [0.0, 0.0, 8.0]);
    let cfg = support::exact_at(0.5);
    // Σ optical depth −ln(1 − α) over the image: the cut-away half counts
    // in proportion to how much μ lets through, the kept half the same at
    // every angle.
    let depth = |img: &[[f32; 4]]| -> f64 {
        img.iter()
            .map(|p| -(1.0 - p[3] as f64).max(1e-12).ln())
            .sum::<f64>()
    };
    let plain = render(&db, &tf, &[], &placement, &view, &cfg);
    let all = depth(&plain);
    let mut last = 0.0;
    let mut alphas = Vec::new();
    for deg in (0..=90).step_by(10) {
        let a = (deg as f64).to_radians();
        let plane = ClipPlane {
            point: [0.0; 3],
            normal: [a.sin(), 0.0, a.cos()],
            thickness: 0.0,
            context: [0.3, 0.7],
        };
        let img = render(&db, &tf, &[Tool::ClipPlane(plane)], &placement, &view, &cfg);
        let m = depth(&img);
        alphas.push((deg, m));
        // While μ = 0 (1 − cos a < f_l: a < 45.6°) the kept half is the
        // same up to the pixel grid (1%); from then on it rises, until
        // μ = 1 on every ray (1 − cos a ≥ f_h: a ≥ 72.5°, and the rays
        // spread by ±1.2°): then the plane changes nothing, and the image
        // is no plane's, bit for bit (no ray gets a break).
        if deg < 50 {
            assert!(m >= last * 0.99, "{deg}°: {m} after {last}");
        } else if deg < 75 {
            assert!(m > last, "{deg}°: {m} after {last}");
        } else {
            assert!(
                img == plain,
                "{deg}°: μ = 1 but the image is not no plane's"
            );
        }
        last = m;
    }
    eprintln!("optical depth by angle: {alphas:?}, no plane {all}");
    let (first, end) = (alphas[0].1, alphas.last().unwrap().1);
    assert!(first < 0.6 * all, "head-on the front half is gone");
    assert!(end > 0.99 * all, "parallel to the view it is all back");
    assert!(end > 1.5 * first);
}

/// Σ optical depth −ln(1 − α) over `pixels` of an image.
fn optical_depth(img: &[[f32; 4]], pixels: impl Iterator<Item = usize>) -> f64 {
    pixels
        .map(|i| -(1.0 - img[i][3] as f64).max(1e-12).ln())
        .sum()
}

/// A probe at the shells' centre with this axis and radius.
fn probe_at_centre(axis: [f64; 3], radius: f64) -> Tool {
    Tool::Probe(Probe {
        axis,
        ..Probe::new([0.0; 3], radius)
    })
}

/// Whether the ray of pixel (i, j) of `view` passes within `r` of `c`.
fn ray_within(view: &View, i: u32, j: u32, c: DVec3, r: f64) -> bool {
    let e = DVec3::from(view.eye);
    let d = (view.screen_point(i, j) - e).normalize();
    let w = c - e;
    (w - d * w.dot(d)).length() < r
}

/// G10 §4 context-preserving probe in the concentric shells, head-on: the
/// image is bit for bit that of no probe on every ray that passes outside
/// its sphere, and changed on the rays through it.
#[test]
fn a_probe_changes_only_the_rays_through_its_sphere() {
    let dir = tempfile::tempdir().unwrap();
    let db = shells(dir.path());
    let tf = translucent();
    let placement = centred([0.0; 3]);
    let view = View::window([64, 64], [0.32, 0.32], [0.0, 0.0, 0.8]);
    let cfg = RenderConfig {
        shading: Shading::Phong,
        ..exact_config()
    };
    let (c, r) = (DVec3::new(0.02, -0.01, 0.03), 0.05);
    let probe = Tool::Probe(Probe::new(c.to_array(), r));
    let plain = render(&db, &tf, &[], &placement, &view, &cfg);
    let img = render(&db, &tf, &[probe], &placement, &view, &cfg);
    let (mut outside, mut same, mut inside, mut changed) = (0, 0, 0, 0);
    let px = 0.32 / 64.0;
    for j in 0..64 {
        for i in 0..64 {
            let k = (j * 64 + i) as usize;
            if !ray_within(&view, i, j, c, r + px) {
                outside += 1;
                same += (img[k].map(f32::to_bits) == plain[k].map(f32::to_bits)) as usize;
            } else if ray_within(&view, i, j, c, r - px) {
                inside += 1;
                changed += (img[k] != plain[k]) as usize;
            }
        }
    }
    eprintln!("probe: {same} of {outside} pixels outside its sphere unchanged, {changed} of {inside} inside changed");
    assert!(outside > 1000 && inside > 100);
    assert_eq!(same, outside, "pixels outside the probe's sphere changed");
    assert!(
        changed as f64 > 0.95 * inside as f64,
        "{changed} of {inside}"
    );
}

/// Looking along its axis at surfaces that face the viewer (the shells'
/// fronts), the probe is transparent at its centre: η ≈ 0 there, so the
/// front half is cleared as if η were 0 everywhere; turning the axis away
/// (ω_a = 0, no contextual edges at all) changes the centre's optical
/// depth by little, while the probe (radius 0.1 m of the shells' 0.135 m)
/// removes over a quarter of it.
#[test]
fn a_probe_facing_the_viewer_is_transparent_at_its_centre() {
    let dir = tempfile::tempdir().unwrap();
    let db = shells(dir.path());
    let tf = translucent();
    let placement = centred([0.0; 3]);
    let view = View::window([64, 64], [0.32, 0.32], [0.0, 0.0, 0.8]);
    let cfg = exact_config();
    let probe = |axis: [f64; 3]| probe_at_centre(axis, 0.1);
    let centre = || (30..34).flat_map(|j| (30..34).map(move |i| j * 64 + i));
    let plain = optical_depth(&render(&db, &tf, &[], &placement, &view, &cfg), centre());
    let facing = render(&db, &tf, &[probe([0.0, 0.0, 1.0])], &placement, &view, &cfg);
    let away = render(
        &db,
        &tf,
        &[probe([0.0, 0.0, -1.0])],
        &placement,
        &view,
        &cfg,
    );
    let (d_facing, d_away) = (
        optical_depth(&facing, centre()),
        optical_depth(&away, centre()),
    );
    eprintln!(
        "probe centre, optical depth: no probe {plain:.3}, axis to the viewer {d_facing:.3}, axis away {d_away:.3}"
    );
    assert!(d_facing < 0.75 * plain, "{d_facing} vs {plain}");
    assert!(
        (d_facing - d_away).abs() < 0.05 * (plain - d_away),
        "{d_facing} vs {d_away}"
    );
}

/// The probe's contextual edges (η's rim, the shells seen edge-on) show
/// when the eye looks along the axis and fade when it looks from 45°: the
/// change the edges make to the image (axis to the viewer against axis
/// away) at two eye positions, the same probe, the same data.
#[test]
fn the_probe_edges_follow_the_view_direction() {
    let dir = tempfile::tempdir().unwrap();
    let db = shells(dir.path());
    let tf = translucent();
    let placement = centred([0.0; 3]);
    let cfg = exact_config();
    let probe = |axis: [f64; 3]| probe_at_centre(axis, 0.08);
    let edges = |eye: [f64; 3]| {
        let view = View::window([64, 64], [0.32, 0.32], eye);
        let on = render(&db, &tf, &[probe([0.0, 0.0, 1.0])], &placement, &view, &cfg);
        let off = render(
            &db,
            &tf,
            &[probe([0.0, 0.0, -1.0])],
            &placement,
            &view,
            &cfg,
        );
        on.iter()
            .zip(&off)
            .map(|(a, b)| (a[3] - b[3]).abs() as f64)
            .sum::<f64>()
    };
    let a = 45f64.to_radians();
    let head_on = edges([0.0, 0.0, 0.8]);
    let side = edges([0.8 * a.sin(), 0.0, 0.8 * a.cos()]);
    eprintln!("probe edges: Σ|Δα| {head_on:.2} looking along the axis, {side:.2} from 45°");
    assert!(head_on > 5.0, "{head_on}");
    assert!(side < 0.2 * head_on, "{side} vs {head_on}");
}

/// G10 §4 band picker on two balls, A (value 100) left and B (value 200)
/// right: looking along its axis only the band (B's values) is seen —
/// every pixel whose ray meets no band value is empty, exactly — and B
/// stays; from 60° the other band returns, and with ω_a = 0 the image is no
/// tool's, bit for bit.
#[test]
fn the_band_picker_shows_only_its_band_along_its_axis() {
    let dir = tempfile::tempdir().unwrap();
    let ball = |x: f64, y: f64, z: f64, cx: f64| {
        let r = DVec3::new(x - cx, y - 16.0, z - 16.0).length();
        ((9.0 - r) / 2.0).clamp(0.0, 1.0)
    };
    let vol = Volume::from_fn([48, 32, 32], [1.0; 3], VoxelType::U8, |i, j, k| {
        let (x, y, z) = (i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5);
        (100.0 * ball(x, y, z, 12.0) + 200.0 * ball(x, y, z, 36.0)).round() as f32
    });
    let db = dir.path().join("balls.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(40.0, [0.2, 0.4, 1.0], 0.0),
        ControlPoint::new(60.0, [0.2, 0.4, 1.0], 0.08),
        ControlPoint::new(255.0, [1.0, 0.6, 0.2], 0.08),
    ])
    .unwrap();
    let placement = centred([0.0; 3]);
    let cfg = exact_config();
    let picker = Tool::BandPicker(BandPicker {
        band: [150.0, 170.0, 230.0, 250.0],
        points: None,
        axis: [0.0, 0.0, 1.0],
        alignment: [0.7, 0.95],
    });
    // Columns left of the middle see only A, the others only B (rays
    // nearly parallel, from 8 m).
    let along = View::window([48, 32], [0.36, 0.24], [0.0, 0.0, 8.0]);
    let plain = render(&db, &tf, &[], &placement, &along, &cfg);
    let img = render(
        &db,
        &tf,
        std::slice::from_ref(&picker),
        &placement,
        &along,
        &cfg,
    );
    let lit = |img: &[[f32; 4]], left: bool| {
        (0..img.len())
            .filter(|&k| ((k % 48) < 24) == left && img[k][3] > 0.01)
            .count()
    };
    let a_pixels = lit(&plain, true);
    let a_left = (0..img.len())
        .filter(|&k| k % 48 < 24 && img[k] != [0.0; 4])
        .count();
    eprintln!(
        "band picker along its axis: A {a_pixels} pixels lit without it, {a_left} with it; B {} and {}",
        lit(&plain, false),
        lit(&img, false)
    );
    assert!(a_pixels > 100);
    assert_eq!(a_left, 0, "pixels whose rays meet no band value are empty");
    // Along its axis the picker acts fully on every ray (ω_a = 1): bricks
    // whose values all miss its band are empty for the frame, neither
    // loaded nor marched (A's, and B's rim).
    let bricks = |tools: &[Tool]| {
        let mut r = Renderer::new(&db, &cfg).unwrap();
        r.set_transfer_function(1, &tf).unwrap();
        r.set_tools(1, tools).unwrap();
        r.converge(&placement, &[along], &cfg, 40).unwrap();
        r.resident_bricks().len()
    };
    let (without, with) = (bricks(&[]), bricks(std::slice::from_ref(&picker)));
    eprintln!("band picker along its axis: {with} bricks resident, {without} without it");
    assert!(with < without, "{with} vs {without}");
    // B's core (values in the band along every ray within 4 px of its
    // centre, at column 33.5, row 15.5) stays; its rim, whose rays meet
    // only values below the band, goes too.
    let core: Vec<usize> = (0..img.len())
        .filter(|&k| {
            let (i, j) = ((k % 48) as f64, (k / 48) as f64);
            (i - 33.5).hypot(j - 15.5) < 4.0
        })
        .collect();
    assert!(core.len() > 30);
    for &k in &core {
        assert!(img[k][3] > 0.01, "B's core pixel {k}: {:?}", img[k]);
    }
    let a = 60f64.to_radians();
    let across = View::window([48, 32], [0.36, 0.24], [8.0 * a.sin(), 0.0, 8.0 * a.cos()]);
    let plain = render(&db, &tf, &[], &placement, &across, &cfg);
    let img = render(&db, &tf, &[picker], &placement, &across, &cfg);
    assert!(mean_alpha(&plain) > 0.01);
    assert!(img == plain, "from 60° the band picker changes nothing");

    // The band taken from the transfer function by index: its point 2 (60)
    // as the plateau, points 1 and 3 (40, 255) as the feet — the same
    // image as that band given by value, and not the image of no tool.
    let by_value = |band: [f64; 4]| {
        Tool::BandPicker(BandPicker {
            band,
            points: None,
            axis: [0.0, 0.0, 1.0],
            alignment: [0.7, 0.95],
        })
    };
    let by_index = Tool::BandPicker(BandPicker {
        band: [0.0; 4],
        points: Some([2, 2]),
        axis: [0.0, 0.0, 1.0],
        alignment: [0.7, 0.95],
    });
    by_index.check("test").unwrap();
    let a = render(&db, &tf, &[by_index], &placement, &along, &cfg);
    let b = render(
        &db,
        &tf,
        &[by_value([40.0, 60.0, 60.0, 255.0])],
        &placement,
        &along,
        &cfg,
    );
    assert!(a == b, "the band by index differs from the band by value");
    let none = render(&db, &tf, &[], &placement, &along, &cfg);
    assert!(a != none);
}

/// Degenerate tools on degenerate data render finite, non-negative
/// images: a constant volume (zero gradient everywhere) and a step volume,
/// a probe of 1 µm and one of 10 m, a band picker whose band is a ramp of
/// width 10⁻⁹ with b0 = b1 = b2, a clip plane along the view, chained, under
/// DVR and MImDA with shading and with the opaque extinctions of a skin.
#[test]
fn degenerate_tools_on_degenerate_data_stay_finite() {
    let dir = tempfile::tempdir().unwrap();
    let constant = Volume::from_fn([16, 16, 16], [1.0; 3], VoxelType::U8, |_, _, _| 100.0);
    let step = Volume::from_fn([16, 16, 16], [1.0; 3], VoxelType::U8, |i, _, _| {
        if i < 8 {
            0.0
        } else {
            255.0
        }
    });
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(50.0, [1.0, 0.5, 0.2], 1e3),
        ControlPoint::new(255.0, [1.0, 1.0, 1.0], 1e3),
    ])
    .unwrap();
    let placement = centred([10.0, 20.0, 0.0]);
    let view = head_on();
    let tools = [
        Tool::Probe(Probe::new([0.0; 3], 1e-6)),
        Tool::BandPicker(BandPicker {
            band: [100.0, 100.0, 100.0, 100.0 + 1e-9],
            points: None,
            axis: [0.0, 0.0, 1.0],
            alignment: [0.7, 0.95],
        }),
        Tool::ClipPlane(ClipPlane {
            point: [0.0; 3],
            normal: [1.0, 0.0, 0.0],
            thickness: 0.0,
            context: [0.0, 1e-9],
        }),
    ];
    let big = [Tool::Probe(Probe::new([0.0, 0.0, 0.05], 10.0))];
    for (name, vol) in [("constant", &constant), ("step", &step)] {
        let db = dir.path().join(format!("{name}.pxo"));
        import_volume(vol, &db, 8, BrickEncoding::F32);
        for mode in [Mode::Dvr, Mode::Mimda] {
            let cfg = RenderConfig {
                mode,
                gamma: if mode == Mode::Mimda { 1.0 } else { 0.0 },
                shading: Shading::Phong,
                ..exact_config()
            };
            for t in [&tools[..], &big[..]] {
                // `render` asserts every pixel finite and within [0, 1].
                let img = render(&db, &tf, t, &placement, &view, &cfg);
                assert!(img.iter().any(|p| p[3] > 0.0) || t.len() == 1, "{name}");
            }
        }
    }
}

/// The emphasis band: behind the plane, within `thickness`, the sliced
/// material goes to full opacity; nothing changes elsewhere.
#[test]
fn the_emphasis_band_makes_the_slice_opaque() {
    let dir = tempfile::tempdir().unwrap();
    let (_, db) = ml32(dir.path());
    let tf = translucent();
    let placement = centred([20.0, 35.0, 0.0]);
    let view = head_on();
    let cfg = exact_config();
    let plane = |thickness| ClipPlane {
        point: [0.0, 0.0, 0.0],
        normal: [0.0, 0.0, 1.0],
        thickness,
        context: [0.3, 0.7],
    };
    let cut = render(
        &db,
        &tf,
        &[Tool::ClipPlane(plane(0.0))],
        &placement,
        &view,
        &cfg,
    );
    let band = render(
        &db,
        &tf,
        &[Tool::ClipPlane(plane(0.01))],
        &placement,
        &view,
        &cfg,
    );
    assert!(mean_alpha(&band) > mean_alpha(&cut) + 0.05);
    // Where the slice holds material the band is opaque.
    let opaque = band.iter().filter(|p| p[3] > 0.999).count();
    assert!(opaque > band.len() / 4, "{opaque} of {}", band.len());
}

/// MImDA with γ = 0 is plain DVR, bit for bit (G10 §4: "smoothly
/// interpolate from plain volume rendering (with γ = 0)"), with and
/// without shading, and whatever the early-termination threshold. At
/// γ = 0 the renderer runs the DVR kernel; at γ = 10⁻¹² the MImDA kernel
/// runs and every β = 1 − γ·δ rounds to 1 in f32, so its operations must
/// be DVR's.
#[test]
fn mimda_with_gamma_zero_is_dvr_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (_, db) = ml32(dir.path());
    let tf = translucent();
    let placement = centred([20.0, 35.0, 0.0]);
    let view = head_on();
    for (shading, early) in [(Shading::None, 1.0), (Shading::Phong, 0.95)] {
        let dvr = RenderConfig {
            shading,
            early_termination: early,
            ..exact_config()
        };
        let a = render(&db, &tf, &[], &placement, &view, &dvr);
        assert!(mean_alpha(&a) > 0.1);
        for gamma in [0.0, 1e-12] {
            let mimda = RenderConfig {
                mode: Mode::Mimda,
                gamma,
                ..dvr.clone()
            };
            let b = render(&db, &tf, &[], &placement, &view, &mimda);
            assert!(a == b, "{shading:?}: γ = {gamma} differs from DVR");
        }
    }
}

/// An outer shell of low importance (blue) around an inner ball of high
/// importance (red): as γ grows, the inner ball shines through (G10 Fig. 6),
/// monotonically.
#[test]
fn an_important_inner_shell_rises_monotonically_with_gamma() {
    let dir = tempfile::tempdir().unwrap();
    let n = 32;
    let c = n as f64 / 2.0;
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        let r = DVec3::new(i as f64 + 0.5 - c, j as f64 + 0.5 - c, k as f64 + 0.5 - c).length();
        if r < 0.25 * n as f64 {
            200.0
        } else if (0.32 * n as f64..0.45 * n as f64).contains(&r) {
            100.0
        } else {
            0.0
        }
    });
    let db = dir.path().join("nested.pxo");
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    let p = |v: f64, color: [f64; 3], tau: f64, imp: f64| {
        ControlPoint::new(v, color, tau).with_importance(imp)
    };
    let blue = [0.0, 0.0, 1.0];
    let red = [1.0, 0.0, 0.0];
    let tf = TransferFunction::from_points(vec![
        p(0.0, blue, 0.0, 0.1),
        p(90.0, blue, 0.0, 0.2),
        p(100.0, blue, 0.2, 0.2),
        p(110.0, blue, 0.0, 0.2),
        p(190.0, red, 0.0, 0.9),
        p(200.0, red, 0.2, 0.9),
    ])
    .unwrap();
    let placement = centred([0.0; 3]);
    let view = View::window([32, 32], [0.32, 0.32], [0.0, 0.0, 1.2]);
    let mut last = -1.0;
    let mut reds = Vec::new();
    for gamma in [0.0, 0.25, 0.5, 0.75, 1.0] {
        let cfg = RenderConfig {
            mode: Mode::Mimda,
            gamma,
            early_termination: 0.99,
            ..exact_config()
        };
        let img = render(&db, &tf, &[], &placement, &view, &cfg);
        let red: f64 = img.iter().map(|p| p[0] as f64).sum::<f64>() / img.len() as f64;
        reds.push((gamma, red));
        assert!(
            red > last,
            "γ = {gamma}: inner contribution {red} after {last}"
        );
        last = red;
    }
    eprintln!("inner (red) contribution by γ: {reds:?}");
    assert!(reds[4].1 > 1.4 * reds[0].1);
}

/// A transparent ball of refraction index `nu` (the rest 1), radius `r`
/// voxels, in an n³ volume.
fn lens(dir: &Path, n: usize, r: f64, nu: f64) -> (std::path::PathBuf, TransferFunction) {
    let c = n as f64 / 2.0;
    let vol = Volume::from_fn([n, n, n], [1.0; 3], VoxelType::U8, |i, j, k| {
        let d = DVec3::new(i as f64 + 0.5 - c, j as f64 + 0.5 - c, k as f64 + 0.5 - c).length();
        (255.0 * (r - d + 0.5).clamp(0.0, 1.0)).round() as f32
    });
    let db = dir.join(format!("lens{nu}.pxo"));
    import_volume(&vol, &db, 8, BrickEncoding::F32);
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0).with_refraction(1.0),
        ControlPoint::new(255.0, [0.0; 3], 0.0).with_refraction(nu),
    ])
    .unwrap();
    (db, tf)
}

/// Snell's law at a sphere in closed form: the direction a ray (volume
/// space) leaves a ball of index `nu` (outside 1) centred at `c` with
/// radius `r`.
fn through_sphere(o: DVec3, d: DVec3, c: DVec3, r: f64, nu: f64) -> DVec3 {
    let hit = |o: DVec3, d: DVec3, far: bool| -> Option<f64> {
        let oc = o - c;
        let b = oc.dot(d);
        let disc = b * b - (oc.length_squared() - r * r);
        (disc > 0.0).then(|| {
            if far {
                -b + disc.sqrt()
            } else {
                -b - disc.sqrt()
            }
        })
    };
    let refract = |d: DVec3, n: DVec3, eta: f64| -> DVec3 {
        let cosi = -n.dot(d);
        let k = 1.0 - eta * eta * (1.0 - cosi * cosi);
        if k < 0.0 {
            d + 2.0 * cosi * n
        } else {
            (eta * d + (eta * cosi - k.sqrt()) * n).normalize()
        }
    };
    let Some(t1) = hit(o, d, false) else {
        return d;
    };
    let p1 = o + d * t1;
    let n1 = (p1 - c) / r;
    let d1 = refract(d, n1, 1.0 / nu);
    if d1.dot(n1) > 0.0 {
        return d1; // total internal reflection: it never enters
    }
    let t2 = hit(p1, d1, true).unwrap();
    let p2 = p1 + d1 * t2;
    refract(d1, -(p2 - c) / r, nu)
}

/// Refraction (G10 §4): ν = 1 everywhere is no refraction, bit for bit; a
/// refracting ball bends rays as Snell's law predicts; nothing is NaN at
/// grazing incidence or under total internal reflection.
#[test]
fn refraction_follows_snells_law() {
    let dir = tempfile::tempdir().unwrap();
    let n = 48;
    let radius = 14.0;
    let placement = centred([0.0; 3]);
    // Nearly parallel rays through the ball and around it.
    let view = View::window([40, 40], [0.24, 0.24], [0.0, 0.0, 4.0]);
    let cfg = support::exact_at(0.25);
    let refracting = RenderConfig {
        refraction: true,
        ..cfg.clone()
    };

    // ν = 1: the refraction kernel gives the plain image.
    let (db1, _) = lens(dir.path(), n, radius, 1.0);
    let tf = translucent();
    let a = render(&db1, &tf, &[], &placement, &view, &cfg);
    let b = render(&db1, &tf, &[], &placement, &view, &refracting);
    assert!(mean_alpha(&a) > 0.01);
    assert!(
        a == b,
        "ν = 1 with refraction on differs from no refraction"
    );

    let exit = [Tool::ExitDirection(Default::default())];
    let ext = [n as f64; 3];
    let centre = DVec3::splat(n as f64 / 2.0);
    for nu in [1.33, 0.6] {
        let (db, tf) = lens(dir.path(), n, radius, nu);
        let img = render(&db, &tf, &exit, &placement, &view, &refracting);
        let mut worst = 0f64;
        let mut sum = 0.0;
        let mut count = 0;
        for j in 0..40u32 {
            for i in 0..40u32 {
                let px = img[(j * 40 + i) as usize];
                assert!(px.iter().all(|v| v.is_finite()), "({i}, {j}): {px:?}");
                if px[3] == 0.0 {
                    continue; // misses the volume's box
                }
                let got = DVec3::new(px[0] as f64, px[1] as f64, px[2] as f64) * 2.0 - DVec3::ONE;
                assert!(
                    (got.length() - 1.0).abs() < 1e-3,
                    "not a unit direction: {got}"
                );
                let (o, d) = view.ray(i, j);
                let (vo, vd) = placement.ray_to_volume(ext, o, d);
                // The impact parameter: only rays that cross the ball well
                // inside its rim are compared (the rim is a voxel-wide
                // blend, where no sharp interface exists).
                let b = (vo - centre).cross(vd).length();
                if b > 0.85 * radius && b < 1.15 * radius {
                    continue;
                }
                // Nor those near the critical angle of total reflection,
                // where the exit direction jumps.
                if nu < 1.0 && (b - nu * radius).abs() < 0.1 * radius {
                    continue;
                }
                let want = through_sphere(vo, vd, centre, radius, nu);
                let err = got.angle_between(want).to_degrees();
                worst = worst.max(err);
                sum += err;
                count += 1;
            }
        }
        eprintln!(
            "ν = {nu}: exit direction against Snell's law in closed form: mean {:.2}°, worst {worst:.2}° over {count} rays",
            sum / count as f64
        );
        assert!(count > 500);
        let mean = sum / count as f64;
        // Measured on lavapipe: ν = 1.33 mean 0.37°, worst 2.1°; ν = 0.6
        // (total reflection for b > 0.6 r) mean 1.9°, worst 14.5°. The
        // ball's rim is a voxel-wide graded layer, not the sharp interface
        // of the closed form, and the strong diverging case feels it most.
        let (mean_max, worst_max) = if nu > 1.0 { (1.0, 4.0) } else { (3.0, 20.0) };
        assert!(mean < mean_max, "mean error {mean}°");
        assert!(worst < worst_max, "worst error {worst}°");
    }
}

/// Every shipped scene loads, with its transfer function, display and
/// tools, and asks for a kernel the naga test validates.
#[test]
fn every_shipped_scene_loads() {
    use parallax_backend::raycast::KernelKey;
    use parallax_common::config::{Display, Scene};
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/scenes");
    let all = KernelKey::all();
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let s = Scene::load(&p).unwrap_or_else(|e| panic!("{e:#}"));
        TransferFunction::load(&s.transfer_function).unwrap_or_else(|e| panic!("{e:#}"));
        Display::load(s.display.as_ref().unwrap()).unwrap_or_else(|e| panic!("{e:#}"));
        let key = KernelKey {
            mimda: s.render.mode == Mode::Mimda,
            refraction: s.render.refraction,
            iso: s.render.mode == Mode::Iso,
            enhancers: s.tools.iter().map(Tool::enhancer).collect(),
            layers: s.layers.len() as u32,
            layer_end: !s.layers.is_empty(),
            labels: s
                .layers
                .iter()
                .enumerate()
                .filter(|(_, l)| l.is_labels())
                .fold(0, |m, (k, _)| m | 1 << k),
        };
        assert!(all.contains(&key), "{}: {key:?}", p.display());
        n += 1;
    }
    assert!(n >= 7, "{n} scenes");
}

/// Per-frame GPU work in the right place: one pipeline per combination a
/// frame uses, built once; frame buffers and the bind group made once and
/// reused while nothing grows; a larger view grows them once; a new
/// transfer function needs a new bind group, not new buffers.
#[test]
fn pipelines_buffers_and_bind_groups_are_reused() {
    let dir = tempfile::tempdir().unwrap();
    let (_, db) = ml32(dir.path());
    let tf = translucent();
    let placement = centred([20.0, 35.0, 0.0]);
    let cfg = RenderConfig {
        accuracy: 1.0,
        ..exact_config()
    };
    let mut r = Renderer::new(&db, &cfg).unwrap();
    r.set_transfer_function(1, &tf).unwrap();
    r.set_tools(1, &[]).unwrap();
    let small = head_on();
    r.converge(&placement, &[small], &cfg, 40).unwrap();
    let settled = r.frame_buffer_counts();
    for i in 0..3 {
        r.frame(100 + i, &placement, &[small], &cfg).unwrap();
    }
    assert_eq!(r.frame_buffer_counts(), settled, "nothing made again");
    let big = View::window([160, 120], [0.4, 0.3], [0.01, 0.005, 0.8]);
    r.frame(200, &placement, &[big], &cfg).unwrap();
    let grown = r.frame_buffer_counts();
    assert!(grown.buffers > settled.buffers, "{settled:?} {grown:?}");
    assert_eq!(grown.bind_groups, settled.bind_groups + 1);
    r.frame(201, &placement, &[small], &cfg).unwrap();
    assert_eq!(r.frame_buffer_counts(), grown, "a smaller frame fits");
    r.set_transfer_function(2, &tf).unwrap();
    r.frame(202, &placement, &[small], &cfg).unwrap();
    let c = r.frame_buffer_counts();
    assert_eq!(
        (c.buffers, c.bind_groups),
        (grown.buffers, grown.bind_groups + 1)
    );
    // Tools switch kernels: one pipeline per combination, built once.
    assert_eq!(r.pipeline_count(), 1);
    let plane = Tool::ClipPlane(ClipPlane {
        point: [0.0; 3],
        normal: [0.0, 0.0, 1.0],
        thickness: 0.0,
        context: [0.3, 0.7],
    });
    for (v, tools) in [(2, vec![plane.clone()]), (3, vec![]), (4, vec![plane])] {
        r.set_tools(v, &tools).unwrap();
        r.frame(300 + v, &placement, &[small], &cfg).unwrap();
    }
    assert_eq!(r.pipeline_count(), 2);
}
