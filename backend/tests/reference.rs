//! The reference integrator against closed-form answers (docs/design.md "What a
//! pixel means") and against brute-force quadrature.

use glam::DVec3;
use parallax_backend::reference::{integrate, render, Tolerance};
use parallax_backend::volume::{Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::tf::{ControlPoint, TransferFunction};

const TIGHT: Tolerance = Tolerance { abs: 1e-11 };

fn tf(points: &[(f64, [f64; 3], f64)]) -> TransferFunction {
    TransferFunction::from_points(
        points
            .iter()
            .map(|&(v, c, t)| ControlPoint::new(v, c, t))
            .collect(),
    )
    .unwrap()
}

/// ∫ τ·c(t)·e^{−τt} dt over a path where τ is constant and c is piecewise
/// linear in t through the knots (t_k, c_k): the exact answer.
fn const_tau(knots: &[(f64, f64)], tau: f64) -> f64 {
    // ∫ τ(a + b t) e^{−τt} = −(a + b t) e^{−τt} − (b/τ) e^{−τt}
    let prim =
        |a: f64, b: f64, t: f64| -(a + b * t) * (-tau * t).exp() - b / tau * (-tau * t).exp();
    knots
        .windows(2)
        .map(|w| {
            let ((t0, c0), (t1, c1)) = (w[0], w[1]);
            let b = (c1 - c0) / (t1 - t0);
            let a = c0 - b * t0;
            prim(a, b, t1) - prim(a, b, t0)
        })
        .sum()
}

#[test]
fn constant_volume_matches_the_closed_form() {
    let vol = Volume::from_fn([7, 5, 9], [1.0, 2.0, 0.5], VoxelType::U8, |_, _, _| 100.0);
    let c = [0.2, 0.5, 0.9];
    let tau = 0.3;
    let f = tf(&[(0.0, c, tau)]);
    // along x through the middle, and obliquely
    for (o, d) in [
        (DVec3::new(-5.0, 5.0, 2.25), DVec3::X),
        (
            DVec3::new(-1.0, -1.0, -1.0),
            DVec3::new(1.0, 1.3, 0.7).normalize(),
        ),
    ] {
        let ext = DVec3::new(7.0, 10.0, 4.5);
        let (t0, t1) = parallax_backend::reference::clip_to_box(o, d, ext).unwrap();
        let len = t1 - t0;
        let a = 1.0 - (-tau * len).exp();
        let got = integrate(&vol, &f, o, d, TIGHT);
        for ch in 0..3 {
            assert!(
                (got[ch] - c[ch] * a).abs() < 1e-9,
                "{got:?} vs {}",
                c[ch] * a
            );
        }
        assert!((got[3] - a).abs() < 1e-9);
    }
}

#[test]
fn linear_ramp_matches_the_closed_form() {
    let n = 12;
    let s = 0.75;
    let vol = Volume::from_fn([n, 3, 3], [s, 1.0, 1.0], VoxelType::U8, |i, _, _| i as f32);
    let tau = 0.4;
    // colour ramps with the value: red 0 → 1 over [0, n−1]; τ constant
    let f = tf(&[
        (0.0, [0.0, 0.0, 0.0], tau),
        ((n - 1) as f64, [1.0, 0.0, 0.0], tau),
    ]);
    let got = integrate(&vol, &f, DVec3::new(-3.0, 1.5, 1.5), DVec3::X, TIGHT);
    // field: 0 until the first voxel centre, linear to n−1 at the last centre, then n−1
    let l = n as f64 * s;
    let knots = [(0.0, 0.0), (0.5 * s, 0.0), (l - 0.5 * s, 1.0), (l, 1.0)];
    let want = const_tau(&knots, tau);
    assert!((got[0] - want).abs() < 1e-9, "{} vs {want}", got[0]);
    assert!((got[3] - (1.0 - (-tau * l).exp())).abs() < 1e-9);
    assert!(got[1].abs() < 1e-15 && got[2].abs() < 1e-15);
}

#[test]
fn slab_matches_the_closed_form() {
    // a slab of value 1 for k in 10..20 inside zeros; the field ramps between
    // the centres of voxels 9 and 10, and of 19 and 20.
    let vol = Volume::from_fn([4, 4, 30], [1.0, 1.0, 1.0], VoxelType::U8, |_, _, k| {
        if (10..20).contains(&k) {
            1.0
        } else {
            0.0
        }
    });
    let tau = 2.5;
    let f = tf(&[(0.0, [0.0, 0.1, 0.0], tau), (1.0, [1.0, 0.1, 0.5], tau)]);
    let got = integrate(&vol, &f, DVec3::new(2.0, 2.0, 40.0), DVec3::NEG_Z, TIGHT);
    // the ray enters at z = 30 (t = 10) and meets the slab from above
    let z_to_t = |z: f64| 40.0 - z;
    let red = [
        (z_to_t(30.0), 0.0),
        (z_to_t(20.5), 0.0),
        (z_to_t(19.5), 1.0),
        (z_to_t(10.5), 1.0),
        (z_to_t(9.5), 0.0),
        (z_to_t(0.0), 0.0),
    ];
    // the integral starts at the box: shift by the entry distance
    let shift = |k: &[(f64, f64)]| k.iter().map(|&(t, c)| (t - 10.0, c)).collect::<Vec<_>>();
    let want_r = const_tau(&shift(&red), tau);
    let green = [(0.0, 0.1), (30.0, 0.1)];
    let want_g = const_tau(&green, tau);
    assert!((got[0] - want_r).abs() < 1e-9, "{} vs {want_r}", got[0]);
    assert!((got[1] - want_g).abs() < 1e-9, "{} vs {want_g}", got[1]);
    assert!((got[2] - 0.5 * want_r).abs() < 1e-9);
}

/// Brute force: midpoint rule with exact per-step transmittance.
fn brute(vol: &Volume, f: &TransferFunction, o: DVec3, d: DVec3, steps: usize) -> [f64; 4] {
    let ext = DVec3::from(vol.info.extent());
    let Some((t0, t1)) = parallax_backend::reference::clip_to_box(o, d, ext) else {
        return [0.0; 4];
    };
    let h = (t1 - t0) / steps as f64;
    let (mut c, mut depth) = ([0.0; 3], 0.0f64);
    for i in 0..steps {
        let t = t0 + (i as f64 + 0.5) * h;
        let op = f.eval(vol.sample((o + d * t).into()));
        let a = -(-op.tau * h).exp_m1();
        let w = if op.tau > 0.0 { a / op.tau } else { h };
        for (cc, e) in c.iter_mut().zip(op.emission) {
            *cc += (-depth).exp() * e * w;
        }
        depth += op.tau * h;
    }
    [c[0], c[1], c[2], -(-depth).exp_m1()]
}

#[test]
fn varying_extinction_and_a_delta_peak_match_brute_force() {
    let vol = Volume::from_fn([16, 16, 16], [1.0, 1.0, 1.0], VoxelType::U8, |i, j, k| {
        ((i * 7 + j * 3 + k * 11) % 23) as f32 * 10.0
    });
    let f = tf(&[
        (0.0, [0.0, 0.0, 0.0], 0.0),
        (50.0, [1.0, 0.5, 0.0], 0.05),
        (100.0, [0.2, 0.9, 0.3], 0.01),
        (150.0, [0.0, 0.0, 1.0], 0.0),
        (151.0, [1.0, 1.0, 1.0], 3.0), // one data step wide peak
        (152.0, [0.0, 0.0, 1.0], 0.0),
        (220.0, [0.5, 0.5, 0.5], 0.2),
    ]);
    let o = DVec3::new(-2.0, 3.1, 4.7);
    let d = DVec3::new(1.0, 0.31, 0.17).normalize();
    let got = integrate(&vol, &f, o, d, TIGHT);
    let want = brute(&vol, &f, o, d, 2_000_000);
    for ch in 0..4 {
        assert!(
            (got[ch] - want[ch]).abs() < 2e-6,
            "channel {ch}: {} vs {}",
            got[ch],
            want[ch]
        );
    }
    assert!(got[3] > 0.1, "the ray sees something: {got:?}");
}

#[test]
fn stiff_and_tiny_extinctions_stay_finite_and_precise() {
    let vol = Volume::from_fn([8, 8, 8], [1.0; 3], VoxelType::U8, |_, _, _| 1.0);
    let o = DVec3::new(4.0, 4.0, -1.0);
    let huge = integrate(
        &vol,
        &tf(&[(0.0, [0.3, 0.6, 0.9], 1e6)]),
        o,
        DVec3::Z,
        Tolerance::default(),
    );
    // the ray stops once the rest could change nothing by more than the tolerance
    assert!(1.0 - huge[3] < 1e-8 && huge[3] <= 1.0, "{huge:?}");
    for (ch, want) in [0.3, 0.6, 0.9].iter().enumerate() {
        assert!((huge[ch] - want).abs() < 1e-7, "{huge:?}");
    }
    let tiny = integrate(
        &vol,
        &tf(&[(0.0, [1.0, 1.0, 1.0], 1e-6)]),
        o,
        DVec3::Z,
        TIGHT,
    );
    // A = 1 − e^{−8e−6}: relative precision, not just absolute
    let want = -(-8e-6f64).exp_m1();
    assert!(((tiny[3] - want) / want).abs() < 1e-9, "{tiny:?}");
    assert!(((tiny[0] - want) / want).abs() < 1e-9);
}

#[test]
fn rays_that_miss_graze_or_start_inside() {
    let vol = Volume::from_fn([8, 8, 8], [1.0; 3], VoxelType::U8, |i, _, _| i as f32);
    let f = tf(&[(0.0, [1.0, 1.0, 1.0], 0.5)]);
    // misses
    assert_eq!(
        integrate(&vol, &f, DVec3::new(-1.0, -1.0, -1.0), DVec3::NEG_X, TIGHT),
        [0.0; 4]
    );
    // along a face: zero length inside, no NaN
    let g = integrate(&vol, &f, DVec3::new(-1.0, 0.0, 0.0), DVec3::X, TIGHT);
    assert!(g.iter().all(|v| v.is_finite() && *v >= 0.0));
    // from the centre: half the box
    let h = integrate(&vol, &f, DVec3::new(4.0, 4.0, 4.0), DVec3::Z, TIGHT);
    assert!((h[3] - (1.0 - (-0.5f64 * 4.0).exp())).abs() < 1e-9);
}

#[test]
fn a_rendered_window_is_finite_and_sees_the_volume() {
    let vol = Volume::from_fn([10, 10, 10], [1.0; 3], VoxelType::U8, |i, j, k| {
        let r2 = [i, j, k]
            .iter()
            .map(|&x| (x as f64 - 4.5).powi(2))
            .sum::<f64>();
        if r2 < 16.0 {
            200.0
        } else {
            0.0
        }
    });
    let f = tf(&[
        (0.0, [0.0; 3], 0.0),
        (100.0, [1.0, 0.8, 0.6], 0.0),
        (200.0, [1.0, 0.8, 0.6], 0.5),
    ]);
    let pl = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [0.0, 30.0, 0.0],
        size: 0.2,
    };
    let view = View::window([16, 12], [0.32, 0.24], [0.0, 0.0, 1.0]);
    let img = render(&vol, &f, &pl, &view, Tolerance::default());
    assert_eq!(img.len(), 16 * 12);
    assert!(img
        .iter()
        .flatten()
        .all(|v| v.is_finite() && *v >= 0.0 && *v <= 1.0 + 1e-12));
    // the centre pixel sees the ball, a corner pixel sees nothing
    assert!(img[6 * 16 + 8][3] > 0.9);
    assert_eq!(img[0], [0.0; 4]);
}
