//! The DVR channels' segment averages in closed form, for
//! `preintegration = "analytic"` (shaders/shared/preint.wgsl
//! `analytic_average`).
//!
//! Between two control points the transfer function is linear in the data
//! value s (docs/design.md "Transfer function"): τ(s) = τa + Δτ·x/w and
//! c(s) = ca + Δc·x/w for x = s − a on a piece [a, a + w]. So τ is linear
//! and k̃ = τ·c quadratic in x,
//!
//!   f(x) = q0 + 2·q1·x + 3·q2·x²,
//!   q0 = (τa, τa·ca), q1 = (Δτ, τa·Δc + ca·Δτ)/(2w), q2 = (0, Δτ·Δc)/(3w²),
//!
//! and its average over [ua, ub] ⊂ [0, w] is exactly
//!
//!   q0 + q1·(ua + ub) + q2·(ua² + ua·ub + ub²),
//!
//! which has no difference of large numbers and no division: the kernel's
//! average over a data segment [lo, hi] is Σ (ub − ua)·that over the pieces
//! the segment meets, over hi − lo. That is Eq. 2 of G10 §4, the exact
//! integral the "exact" table gives for a linear scalar between samples,
//! computed per segment from a few constants instead of read from a table:
//! on a CPU device a texture read is a gather per channel and lane, dearer
//! than a dozen products per piece.
//!
//! Pieces where τ is 0 at both ends (so k̃ ≡ 0) add nothing and are left
//! out. Beyond the first and last point the function is constant: where the
//! data range reaches past them, a constant piece covers the rest.

use super::function::{ControlPoint, TransferFunction};

/// The most pieces the kernel integrates (its uniform's size); a function
/// with more, over the data range, is looked up in a table instead.
pub const MAX_PIECES: usize = 16;

/// Largest magnitude of a coefficient term (|q|·w^k) and of a piece's
/// integral accepted: far inside f32's range, so that the kernel's sums of
/// products stay finite.
const MAX_TERM: f64 = 1e30;

/// One piece: [start, start + width] and the coefficients of
/// (τ, k̃r, k̃g, k̃b) in x = s − start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    pub start: f64,
    pub width: f64,
    pub q0: [f64; 4],
    pub q1: [f64; 4],
    pub q2: [f64; 4],
}

impl Piece {
    /// The piece's four vec4s as the kernel reads them: (start, width, 0,
    /// 0), q0, q1, q2.
    pub fn gpu(&self) -> [[f32; 4]; 4] {
        let f = |v: [f64; 4]| v.map(|x| x as f32);
        [
            [self.start as f32, self.width as f32, 0.0, 0.0],
            f(self.q0),
            f(self.q1),
            f(self.q2),
        ]
    }

    /// The same polynomial with x counted from start + x0, over the rest of
    /// the piece (x0 < 0: reaching |x0| further back).
    fn recentred(&self, x0: f64) -> Piece {
        Piece {
            start: self.start + x0,
            width: self.width - x0,
            q0: std::array::from_fn(|c| {
                self.q0[c] + 2.0 * self.q1[c] * x0 + 3.0 * self.q2[c] * x0 * x0
            }),
            q1: std::array::from_fn(|c| self.q1[c] + 3.0 * self.q2[c] * x0),
            q2: self.q2,
        }
    }

    /// ∫ over [lo, hi] ∩ the piece of (τ, k̃), by the kernel's formula.
    fn integral(&self, lo: f64, hi: f64) -> [f64; 4] {
        let ua = (lo - self.start).clamp(0.0, self.width);
        let ub = (hi - self.start).clamp(0.0, self.width);
        let (s1, s2) = (ua + ub, ua * ua + ua * ub + ub * ub);
        std::array::from_fn(|c| (ub - ua) * (self.q0[c] + self.q1[c] * s1 + self.q2[c] * s2))
    }
}

/// The pieces of a transfer function over a dataset's value range, and
/// what the kernel needs besides: the range, to which sample values are
/// clamped (as the tables clamp them), and the width a shorter segment is
/// widened to.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedForm {
    pub pieces: Vec<Piece>,
    pub vmin: f64,
    pub vmax: f64,
    /// 2⁻¹⁸ of the largest magnitude in the range (64 f32 steps of it):
    /// widening then moves the ends, and a segment of equal ends has a
    /// width to divide by. The pieces reach this far beyond the range, so
    /// a widened segment at its edge integrates over its whole width.
    pub eps: f64,
}

/// The uniform the kernel reads (WGSL `TfPieces`): (vmin, vmax, eps,
/// pieces), then [`MAX_PIECES`] pieces of four vec4s.
pub type GpuPieces = [[f32; 4]; 1 + 4 * MAX_PIECES];

impl ClosedForm {
    /// The pieces of `tf` over [vmin, vmax] (vmin < vmax), or `None` where
    /// there are more than [`MAX_PIECES`] or a coefficient is too large for
    /// f32 sums (an extinction near [`super::MAX_EXTINCTION`] over a
    /// narrow piece): a table then serves.
    pub fn new(tf: &TransferFunction, vmin: f64, vmax: f64) -> Option<Self> {
        let m = vmin.abs().max(vmax.abs()).max(vmax - vmin);
        let eps = if m > 0.0 { m * 2f64.powi(-18) } else { 1e-30 };
        let mut pieces = pieces(tf, vmin, vmax)?;
        // A piece that reaches an end of the range goes on past it by eps,
        // its own polynomial continued (within eps·f' of the constant the
        // function is beyond its last point: 2⁻¹⁸ of the range's scale).
        if let Some(p) = pieces.first_mut().filter(|p| p.start <= vmin) {
            *p = p.recentred(-eps);
        }
        if let Some(p) = pieces.last_mut().filter(|p| p.start + p.width >= vmax) {
            p.width += eps;
        }
        Some(ClosedForm {
            pieces,
            vmin,
            vmax,
            eps,
        })
    }

    /// The average of (τ, k̃r, k̃g, k̃b) over the data segment between `a`
    /// and `b` (either order), as the kernel computes it but in f64: both
    /// ends clamped to the range, a segment shorter than `eps` widened to
    /// it about its middle.
    pub fn average(&self, a: f64, b: f64) -> [f64; 4] {
        let (a, b) = (a.clamp(self.vmin, self.vmax), b.clamp(self.vmin, self.vmax));
        let (mut lo, mut hi) = (a.min(b), a.max(b));
        let widen = 0.5 * (self.eps - (hi - lo)).max(0.0);
        lo -= widen;
        hi += widen;
        let mut sum = [0.0; 4];
        for p in &self.pieces {
            let i = p.integral(lo, hi);
            for c in 0..4 {
                sum[c] += i[c];
            }
        }
        sum.map(|x| (x / (hi - lo)).max(0.0))
    }

    /// The kernel's uniform.
    pub fn gpu(&self) -> GpuPieces {
        let mut out = [[0f32; 4]; 1 + 4 * MAX_PIECES];
        out[0] = [
            self.vmin as f32,
            self.vmax as f32,
            self.eps as f32,
            self.pieces.len() as f32,
        ];
        for (i, p) in self.pieces.iter().enumerate() {
            out[1 + 4 * i..5 + 4 * i].copy_from_slice(&p.gpu());
        }
        out
    }
}

/// The pieces of `tf` over [vmin, vmax] where τ is not ≡ 0, or `None` (see
/// [`ClosedForm::new`]).
fn pieces(tf: &TransferFunction, vmin: f64, vmax: f64) -> Option<Vec<Piece>> {
    let pts = tf.points();
    let first = pts.first()?;
    let last = pts.last()?;
    let mut out = Vec::new();
    let mut push = |p: Piece| {
        if p.width > 0.0 && (p.q0[0] != 0.0 || p.q1[0] != 0.0) {
            out.push(p);
        }
    };
    // Beyond an end point the function is that point's, constant.
    let constant = |start: f64, end: f64, p: &ControlPoint| {
        let c = p.color.map(|c| p.extinction * c);
        Piece {
            start,
            width: end - start,
            q0: [p.extinction, c[0], c[1], c[2]],
            q1: [0.0; 4],
            q2: [0.0; 4],
        }
    };
    if vmin < first.value {
        push(constant(vmin, first.value.min(vmax), first));
    }
    for w in pts.windows(2) {
        let (p, n) = (&w[0], &w[1]);
        // The part of [p, n] inside the data range, in x from p's value.
        let (a, b) = (p.value.max(vmin), n.value.min(vmax));
        let width = n.value - p.value;
        if b <= a || width <= 0.0 {
            continue;
        }
        let dt = n.extinction - p.extinction;
        let mut q0 = [p.extinction; 4];
        let mut q1 = [dt / (2.0 * width); 4];
        let mut q2 = [0.0; 4];
        for c in 0..3 {
            let dc = n.color[c] - p.color[c];
            q0[c + 1] = p.extinction * p.color[c];
            q1[c + 1] = (p.extinction * dc + p.color[c] * dt) / (2.0 * width);
            q2[c + 1] = dt * dc / (3.0 * width * width);
        }
        // Counted from a: f(x + x0) = q0' + 2·q1'·x + 3·q2'·x², x0 = a − p.
        let whole = Piece {
            start: p.value,
            width,
            q0,
            q1,
            q2,
        };
        let mut piece = whole.recentred(a - p.value);
        piece.width = b - a;
        push(piece);
    }
    if vmax > last.value {
        push(constant(last.value.max(vmin), vmax, last));
    }
    // Each coefficient, each term of the average (|q1|·w, |q2|·w²) and of
    // the integral (times w again) within MAX_TERM.
    let fits = out.iter().all(|p| {
        let w = p.width;
        let ok = |x: f64| x.is_finite() && x.abs() <= MAX_TERM;
        ok(p.start)
            && ok(w)
            && (0..4).all(|c| {
                let terms = [p.q0[c], p.q1[c] * w, p.q2[c] * w * w];
                [p.q1[c], p.q2[c]].into_iter().all(ok) && terms.iter().all(|&t| ok(t) && ok(t * w))
            })
    });
    (out.len() <= MAX_PIECES && fits).then_some(out)
}
