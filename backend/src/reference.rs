//! The reference integrator: the exact emission–absorption integral of
//! docs/design.md "What a pixel means", in f64, on the raw volume (not the octree).
//! Every image the renderer makes is measured against it.
//!
//! Along a ray the field s(t) (trilinear, clamped to the edge voxels) is a
//! polynomial of degree ≤ 3 between two crossings of the planes through voxel
//! centres, and the transfer function is linear in s between control values.
//! So the ray is cut at every such plane and at every t where s(t) crosses a
//! control value; on each piece the integrand is smooth and
//!
//!   C += T·∫ k̃(t)·exp(−∫ₐᵗ τ) dt,   T ← T·exp(−∫ₐᵇ τ)
//!
//! is evaluated by 8-point Gauss–Legendre quadrature, the inner optical depth
//! at each node by the spectral integration matrix of the same nodes. Each
//! piece is bisected until whole and halves agree to the tolerance. The ray
//! stops once the transmittance T is below the tolerance (colours are ≤ 1, so
//! the rest can add at most T).

use crate::volume::Volume;
use glam::DVec3;
use parallax_common::camera::{Placement, View};
use parallax_common::tf::TransferFunction;
use parallax_common::tools::ClipPlane;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Premultiplied RGBA of one ray.
pub type Rgba = [f64; 4];

/// Gauss–Legendre nodes and weights on [−1, 1], n = 8.
const GL_X: [f64; 8] = [
    -0.960_289_856_497_536_3,
    -0.796_666_477_413_626_7,
    -0.525_532_409_916_329,
    -0.183_434_642_495_649_8,
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
const GL_W: [f64; 8] = [
    0.101_228_536_290_376_3,
    0.222_381_034_453_374_5,
    0.313_706_645_877_887_3,
    0.362_683_783_378_362,
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// S[i][j] = ∫_{−1}^{x_i} L_j(x) dx, L_j the Lagrange basis on the nodes:
/// the optical depth from the start of a piece to node i is Σ_j S[i][j]·τ_j
/// (exact for τ of degree ≤ 7 along the piece).
fn integration_matrix() -> &'static [[f64; 8]; 8] {
    static S: OnceLock<[[f64; 8]; 8]> = OnceLock::new();
    S.get_or_init(|| {
        let lagrange = |j: usize, x: f64| {
            (0..8)
                .filter(|&m| m != j)
                .map(|m| (x - GL_X[m]) / (GL_X[j] - GL_X[m]))
                .product::<f64>()
        };
        let mut s = [[0.0; 8]; 8];
        for i in 0..8 {
            let half = 0.5 * (GL_X[i] + 1.0);
            for (j, sij) in s[i].iter_mut().enumerate() {
                // L_j has degree 7: 8-point Gauss on [−1, x_i] is exact.
                *sij = (0..8)
                    .map(|k| GL_W[k] * half * lagrange(j, -1.0 + half * (GL_X[k] + 1.0)))
                    .sum();
            }
        }
        s
    })
}

/// Settings of the integrator.
#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    /// Absolute error allowed in each premultiplied channel of a pixel.
    pub abs: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance { abs: 1e-7 }
    }
}

/// The integral along the ray origin + t·dir (volume space, dir a unit
/// vector, t ≥ 0 in data length units) through the volume's box.
pub fn integrate(
    vol: &Volume,
    tf: &TransferFunction,
    origin: DVec3,
    dir: DVec3,
    tol: Tolerance,
) -> Rgba {
    integrate_kept(vol, tf, origin, dir, tol, &[])
}

/// The integral along the part of the ray that lies in every kept
/// half-space `normal·q + offset ≤ 0` (volume space): what clip planes whose
/// context factor is 0 leave of the volume (G10 §4, viewed head-on).
pub fn integrate_kept(
    vol: &Volume,
    tf: &TransferFunction,
    origin: DVec3,
    dir: DVec3,
    tol: Tolerance,
    keep: &[(DVec3, f64)],
) -> Rgba {
    let ext = DVec3::from(vol.info.extent());
    let Some((mut t0, mut t1)) = clip_to_box(origin, dir, ext) else {
        return [0.0; 4];
    };
    for &(n, p) in keep {
        let (a, b) = (n.dot(origin) + p, n.dot(dir));
        if b.abs() < 1e-300 {
            if a > 0.0 {
                return [0.0; 4];
            }
        } else if b > 0.0 {
            t1 = t1.min(-a / b);
        } else {
            t0 = t0.max(-a / b);
        }
    }
    if t1 <= t0 {
        return [0.0; 4];
    }
    let breaks = cell_crossings(vol, origin, dir, t0, t1);
    let kinks = tf.control_values();
    let field = |t: f64| vol.sample((origin + dir * t).into());
    let mut acc = Accumulator::new(tol.abs, t1 - t0);
    for w in breaks.windows(2) {
        let (a, b) = (w[0], w[1]);
        // A cell whose eight voxels are all no data (NaN) adds nothing.
        if b <= a || field(0.5 * (a + b)).is_nan() {
            continue;
        }
        for piece in smooth_pieces(&field, a, b, &kinks).windows(2) {
            acc.piece(&field, tf, piece[0], piece[1]);
            if acc.done() {
                return acc.rgba();
            }
        }
    }
    acc.rgba()
}

/// The parameter interval where the ray is inside [0, ext]³, if any.
pub fn clip_to_box(o: DVec3, d: DVec3, ext: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if d[a].abs() < 1e-300 {
            if o[a] < 0.0 || o[a] > ext[a] {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((0.0 - o[a]) / d[a], (ext[a] - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t1 > t0).then_some((t0, t1))
}

/// t0, every crossing of a plane through voxel centres inside (t0, t1), t1.
fn cell_crossings(vol: &Volume, o: DVec3, d: DVec3, t0: f64, t1: f64) -> Vec<f64> {
    let mut ts = vec![t0, t1];
    for a in 0..3 {
        if d[a] == 0.0 {
            continue;
        }
        let s = vol.info.spacing[a];
        for i in 0..vol.info.dims[a] {
            let t = (((i as f64 + 0.5) * s) - o[a]) / d[a];
            if t > t0 && t < t1 {
                ts.push(t);
            }
        }
    }
    ts.sort_by(f64::total_cmp);
    ts
}

/// Cuts [a, b] (inside one cell, where s(t) is a cubic) at every t where the
/// field crosses a transfer-function control value.
fn smooth_pieces(field: &impl Fn(f64) -> f64, a: f64, b: f64, kinks: &[f64]) -> Vec<f64> {
    let h = b - a;
    // The cubic p(u) = s(a + u·h) from its values at u = 0, ⅓, ⅔, 1.
    let f = [
        field(a),
        field(a + h / 3.0),
        field(a + 2.0 * h / 3.0),
        field(b),
    ];
    let (lo, hi) = f
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, m), &v| {
            (l.min(v), m.max(v))
        });
    let mut cuts = vec![a, b];
    if hi == lo {
        return cuts; // a cubic with four equal values is constant
    }
    // Power-basis coefficients of p from Newton forward differences on the
    // nodes x = 3u = 0, 1, 2, 3.
    let d1 = [f[1] - f[0], f[2] - f[1], f[3] - f[2]];
    let d2 = [d1[1] - d1[0], d1[2] - d1[1]];
    let d3 = d2[1] - d2[0];
    let (a1, a2, a3) = (d1[0] - d2[0] / 2.0 + d3 / 3.0, (d2[0] - d3) / 2.0, d3 / 6.0);
    let (c1, c2, c3) = (3.0 * a1, 9.0 * a2, 27.0 * a3);
    let p = |u: f64| f[0] + u * (c1 + u * (c2 + u * c3));
    // Monotonic pieces: split at the roots of p'(u) = c1 + 2c2 u + 3c3 u².
    let mut us = vec![0.0, 1.0];
    for r in quadratic_roots(3.0 * c3, 2.0 * c2, c1) {
        if r > 0.0 && r < 1.0 {
            us.push(r);
        }
    }
    us.sort_by(f64::total_cmp);
    for w in us.windows(2) {
        let (ua, ub) = (w[0], w[1]);
        let (pa, pb) = (p(ua), p(ub));
        let (mn, mx) = (pa.min(pb), pa.max(pb));
        for &k in kinks {
            if k > mn && k < mx {
                // bisection on a monotonic piece: converges to the crossing
                let (mut l, mut r) = (ua, ub);
                let rising = pb > pa;
                for _ in 0..64 {
                    let m = 0.5 * (l + r);
                    if (p(m) < k) == rising {
                        l = m;
                    } else {
                        r = m;
                    }
                }
                cuts.push(a + 0.5 * (l + r) * h);
            }
        }
    }
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    cuts
}

/// Real roots of a·x² + b·x + c (a may be 0).
fn quadratic_roots(a: f64, b: f64, c: f64) -> Vec<f64> {
    let scale = a.abs().max(b.abs()).max(c.abs());
    if scale == 0.0 {
        return vec![];
    }
    if a.abs() <= 1e-14 * scale {
        return if b.abs() > 1e-14 * scale {
            vec![-c / b]
        } else {
            vec![]
        };
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return vec![];
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let mut r = vec![q / a];
    if q != 0.0 {
        r.push(c / q);
    }
    r
}

/// Front-to-back accumulation over smooth pieces.
struct Accumulator {
    color: [f64; 3],
    /// Transmittance so far, and the optical depth it came from (kept so
    /// that opacity 1 − T keeps its precision when T is close to 1).
    depth: f64,
    tol: f64,
    length: f64,
}

struct PieceResult {
    depth: f64,
    emission: [f64; 3],
}

impl Accumulator {
    fn new(tol: f64, length: f64) -> Self {
        Accumulator {
            color: [0.0; 3],
            depth: 0.0,
            tol,
            length: length.max(1e-300),
        }
    }

    fn transmittance(&self) -> f64 {
        (-self.depth).exp()
    }

    /// Once T is below the tolerance, the rest of the ray can change no
    /// channel by more than it.
    fn done(&self) -> bool {
        self.transmittance() < 0.01 * self.tol
    }

    fn rgba(&self) -> Rgba {
        let a = -(-self.depth).exp_m1();
        [self.color[0], self.color[1], self.color[2], a]
    }

    /// Integrates a smooth piece [a, b], bisecting until converged.
    fn piece(&mut self, field: &impl Fn(f64) -> f64, tf: &TransferFunction, a: f64, b: f64) {
        let mut stack = vec![(a, b, gauss(field, tf, a, b))];
        while let Some((a, b, whole)) = stack.pop() {
            let m = 0.5 * (a + b);
            let left = gauss(field, tf, a, m);
            let right = gauss(field, tf, m, b);
            let t_left = (-left.depth).exp();
            let halves = PieceResult {
                depth: left.depth + right.depth,
                emission: std::array::from_fn(|c| left.emission[c] + t_left * right.emission[c]),
            };
            let t = self.transmittance();
            let err = t
                * ((whole.depth - halves.depth).abs().min(1.0)
                    + (0..3)
                        .map(|c| (whole.emission[c] - halves.emission[c]).abs())
                        .fold(0.0, f64::max));
            let allowed = self.tol * ((b - a) / self.length).max(1e-3);
            // A piece must also be optically thin: where τ·h is large the
            // emission is squeezed against the piece's start, between the
            // nodes, and whole and halves can agree on a wrong answer.
            let thin = whole.depth.max(halves.depth) <= 0.5;
            if (err <= allowed && thin) || (b - a) <= 1e-13 * self.length.max(1.0) {
                for c in 0..3 {
                    self.color[c] += t * halves.emission[c];
                }
                self.depth += halves.depth;
                if self.done() {
                    return;
                }
            } else {
                stack.push((m, b, right));
                stack.push((a, m, left));
            }
        }
    }
}

/// 8-point Gauss–Legendre estimate of a piece's optical depth and of its
/// emission attenuated from the piece's start.
fn gauss(field: &impl Fn(f64) -> f64, tf: &TransferFunction, a: f64, b: f64) -> PieceResult {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let mut tau = [0.0; 8];
    let mut em = [[0.0; 3]; 8];
    for k in 0..8 {
        let v = field(mid + half * GL_X[k]);
        if v.is_nan() {
            continue; // no data: transparent
        }
        let o = tf.eval(v);
        tau[k] = o.tau;
        em[k] = o.emission;
    }
    let s = integration_matrix();
    let mut depth = 0.0;
    let mut emission = [0.0; 3];
    for i in 0..8 {
        depth += GL_W[i] * half * tau[i];
        let inner: f64 = (0..8).map(|j| s[i][j] * tau[j]).sum::<f64>() * half;
        let att = (-inner.max(0.0)).exp();
        for c in 0..3 {
            emission[c] += GL_W[i] * half * em[i][c] * att;
        }
    }
    PieceResult {
        depth,
        emission: emission.map(|e| e.max(0.0)),
    }
}

/// Renders a whole view with the reference integrator: premultiplied RGBA,
/// row 0 at the top.
pub fn render(
    vol: &Volume,
    tf: &TransferFunction,
    placement: &Placement,
    view: &View,
    tol: Tolerance,
) -> Vec<Rgba> {
    render_clipped(vol, tf, placement, view, tol, &[])
}

/// [`render`] with the half-spaces that clip planes cut away removed (their
/// context factor taken as 0, as when viewed head-on).
pub fn render_clipped(
    vol: &Volume,
    tf: &TransferFunction,
    placement: &Placement,
    view: &View,
    tol: Tolerance,
    planes: &[ClipPlane],
) -> Vec<Rgba> {
    let [w, h] = view.resolution;
    let ext = vol.info.extent();
    let keep: Vec<(DVec3, f64)> = planes
        .iter()
        .map(|c| {
            let v = c.in_volume(placement, ext);
            (v.normal, v.offset)
        })
        .collect();
    (0..w * h)
        .into_par_iter()
        .map(|p| {
            let (o, d) = view.ray(p % w, p / w);
            let (vo, vd) = placement.ray_to_volume(ext, o, d);
            integrate_kept(vol, tf, vo, vd, tol, &keep)
        })
        .collect()
}
