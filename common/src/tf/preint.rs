//! Pre-integration of a transfer function (G10 §4 Eq. 2), without the
//! cancellation of a running integral.
//!
//! G10 stores, per attribute f ∈ {τ, k̃, ι, ν}, the running integral
//! F(s) = ∫₀ˢ f and takes the segment average as (F(b) − F(a))/(b − a).
//! When extinction spans many orders of magnitude (τ = 1e6 somewhere below,
//! τ = 1e-6 here) F(b) − F(a) is the small difference of two large numbers and
//! loses every significant digit. This table never subtracts: it keeps the
//! node values and a dyadic pyramid of bin integrals, all ≥ 0, and assembles
//! any integral from at most ~2·log₂N non-negative terms plus two exact
//! partial-bin trapezoids.
//!
//! Table coordinates: u = (s − vmin)/Δ with Δ = (vmax − vmin)/N, so node i is
//! at u = i and every bin has width 1. Within a bin the table's f is the
//! quadratic through the two node values and the value at the bin's
//! midpoint; this is the transfer function as the renderer sees it. Between
//! control points τ, c, ι and ν are linear and the emission k̃ = τ·c is
//! quadratic, so in every bin without a control point inside it the table is
//! the transfer function exactly — with integer data and integer control
//! values (bin width 1) that is every bin. A bin with a control point
//! strictly inside it keeps the linear interpolant of its two nodes (its
//! midpoint entry is their mean), which can never be negative. Outside
//! [vmin, vmax] f is constant (f(vmin) below, f(vmax) above).
//!
//! (A linear interpolant of k̃ alone, as tables of node values give, errs by
//! up to |τ′c′|·Δ²/4 inside a bin: for a one-value-wide extinction peak of
//! τ = 3 that is three quarters of the peak's emission, an error that no step
//! size removes.)

use anyhow::{bail, Result};

use super::function::{TransferFunction, MAX_ABS_VALUE};

/// Largest number of bins a table may have.
pub const MAX_BINS: usize = 1 << 20;

/// Largest number of pyramid levels any table can have (N ≤ 2^20 needs 21).
pub const MAX_LEVELS: usize = 32;

/// Eq. 2's ε of G10 (relative to the data range). Not needed by this table,
/// whose same-bin branch is exact without a threshold; kept for callers that
/// want to reproduce G10's behaviour.
pub const G10_EPSILON: f64 = 1e-4;

/// Bin count used for data that is not integer-valued or spans a wide range.
pub const DEFAULT_BINS: usize = 4096;

/// The pre-integrated attributes (channels) of a table, in storage order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Extinction τ.
    Tau = 0,
    /// Emission k̃ = τ·c, red.
    EmissionR = 1,
    /// Emission k̃ = τ·c, green.
    EmissionG = 2,
    /// Emission k̃ = τ·c, blue.
    EmissionB = 3,
    /// Importance ι.
    Importance = 4,
    /// Refraction index ν.
    Refraction = 5,
}

impl Channel {
    /// Number of channels.
    pub const COUNT: usize = 6;

    /// Every channel, in storage order.
    pub const ALL: [Channel; Channel::COUNT] = [
        Channel::Tau,
        Channel::EmissionR,
        Channel::EmissionG,
        Channel::EmissionB,
        Channel::Importance,
        Channel::Refraction,
    ];

    /// Position of the channel in storage order.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The channel's value in a set of optical properties.
    pub fn of(self, o: &super::Optics) -> f64 {
        match self {
            Channel::Tau => o.tau,
            Channel::EmissionR => o.emission[0],
            Channel::EmissionG => o.emission[1],
            Channel::EmissionB => o.emission[2],
            Channel::Importance => o.importance,
            Channel::Refraction => o.refraction,
        }
    }
}

/// Segment averages of every channel over a data-value segment [a, b]: what
/// G10 Eq. 2 calls f_i, for one integration step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentOptics {
    /// Average extinction τ̄.
    pub tau: f64,
    /// Average emission k̃̄ (extinction-weighted colour).
    pub emission: [f64; 3],
    /// Average importance ῑ.
    pub importance: f64,
    /// Average refraction index ν̄.
    pub refraction: f64,
}

impl SegmentOptics {
    /// Opacity of a step of length `d`: α = 1 − exp(−τ̄·d) (G10 §4).
    pub fn alpha(&self, d: f64) -> f64 {
        alpha(self.tau, d)
    }

    /// Opacity-weighted (premultiplied) colour of a step of length `d`:
    /// k̃̄/τ̄ · α (G10 §4).
    pub fn premultiplied_color(&self, d: f64) -> [f64; 3] {
        premultiplied_color(self.emission, self.tau, d)
    }
}

/// NaN and negative values become 0.
fn non_negative(x: f64) -> f64 {
    if x > 0.0 {
        x
    } else {
        0.0
    }
}

/// Optical depth τ̄·d, with NaN or negative inputs taken as 0 and 0·∞ = 0.
fn optical_depth(tau_avg: f64, d: f64) -> f64 {
    let (t, d) = (non_negative(tau_avg), non_negative(d));
    if t == 0.0 || d == 0.0 {
        0.0
    } else {
        t * d
    }
}

/// Opacity of a step: α = 1 − exp(−τ̄·d), computed as −expm1(−τ̄·d) so that
/// it keeps full relative precision when τ̄·d is tiny, and is exactly 1 when
/// τ̄·d is large. Always in [0, 1]; NaN or negative inputs count as 0.
pub fn alpha(tau_avg: f64, d: f64) -> f64 {
    -(-optical_depth(tau_avg, d)).exp_m1()
}

/// α/τ̄: the factor that turns an average emission k̃̄ into a premultiplied
/// colour, k̃̄·α/τ̄. Computed as d·(−expm1(−x)/x) with x = τ̄·d, which tends
/// to d as x → 0 and to 1/τ̄ as x → ∞. Returns 0 when τ̄ = 0 (no extinction,
/// no premultiplied colour). Always finite and ≥ 0 for finite τ̄ > 0.
pub fn emission_weight(tau_avg: f64, d: f64) -> f64 {
    let (t, d) = (non_negative(tau_avg), non_negative(d));
    if t == 0.0 || d == 0.0 {
        return 0.0;
    }
    let x = t * d;
    if x.is_finite() {
        // −expm1(−x)/x ∈ (0, 1]; for subnormal x, −expm1(−x) = x exactly.
        let phi = -(-x).exp_m1() / x;
        (d * phi).min(f64::MAX)
    } else {
        // α = 1 exactly.
        1.0 / t
    }
}

/// Premultiplied colour of a step of length `d` from average emission k̃̄ and
/// average extinction τ̄: k̃̄/τ̄·α (G10 §4), computed as k̃̄·(α/τ̄) with
/// [`emission_weight`]. Zero when τ̄ = 0; never NaN or negative.
pub fn premultiplied_color(emission_avg: [f64; 3], tau_avg: f64, d: f64) -> [f64; 3] {
    let w = emission_weight(tau_avg, d);
    emission_avg.map(|e| {
        let e = non_negative(e).min(f64::MAX);
        if w == 0.0 || e == 0.0 {
            0.0
        } else {
            (e * w).min(f64::MAX)
        }
    })
}

/// One channel: node values and the dyadic pyramid of bin integrals.
#[derive(Clone, Debug)]
struct ChannelTable {
    /// f at the N+1 nodes.
    nodes: Vec<f64>,
    /// f at the N bin midpoints (the mean of the two nodes where a control
    /// point lies inside the bin).
    mids: Vec<f64>,
    /// `levels[k][j]` = ∫ f du over bins [j·2^k, (j+1)·2^k) (u in bins, so
    /// level 0 is Simpson's (f_j + 4·m_j + f_{j+1})/6, exact for the in-bin
    /// quadratic); N >> k entries.
    levels: Vec<Vec<f64>>,
}

/// The average over [ta, tb] ⊆ [0, 1], ta ≤ tb, of the in-bin quadratic
/// through the node values a (t = 0), b (t = 1) and the midpoint value m:
/// f at the centre (Lagrange form, exactly a and b at the ends) plus
/// f''·w²/24 with f'' = 4·(a + b − 2m). Exact; no division, so ta == tb
/// gives f(ta). Never negative.
#[inline]
fn bin_average(a: f64, m: f64, b: f64, ta: f64, tb: f64) -> f64 {
    let t = 0.5 * (ta + tb);
    let w = tb - ta;
    let f = a * (1.0 - t) * (1.0 - 2.0 * t) + 4.0 * m * t * (1.0 - t) + b * t * (2.0 * t - 1.0);
    (f + (a + b - 2.0 * m) * (w * w / 6.0)).max(0.0)
}

/// How [`PreintTable::gpu_layout`] lays the table out in one `f32` array.
///
/// Channel `c` (in [`Channel`] order) occupies
/// `[c·channel_stride, (c+1)·channel_stride)`. Within a channel block the
/// N+1 node values come first (offset 0), then pyramid level k
/// (k < `levels`) at `level_offsets[k]`, with `n_bins >> k` entries: entry j
/// is ∫ f du over bins [j·2^k, (j+1)·2^k), in units of bins (multiply by
/// `bin_width` for data units). The N bin midpoint values follow at
/// `mid_offset`. Data value s maps to u = (s − vmin)/bin_width.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreintLayout {
    pub n_bins: u32,
    /// Number of pyramid levels (level 0 = single bins).
    pub levels: u32,
    /// Number of channels ([`Channel::COUNT`]).
    pub channels: u32,
    /// `f32`s per channel block.
    pub channel_stride: u32,
    /// Offset of pyramid level k within a channel block (unused entries 0).
    pub level_offsets: [u32; MAX_LEVELS],
    /// Offset of the N bin midpoint values within a channel block.
    pub mid_offset: u32,
    pub vmin: f64,
    pub vmax: f64,
    pub bin_width: f64,
}

/// Pre-integration table of a transfer function over the data range
/// [vmin, vmax] with N bins (G10 §4 Eq. 2, with a cancellation-free layout;
/// see the module documentation).
#[derive(Clone, Debug)]
pub struct PreintTable {
    vmin: f64,
    vmax: f64,
    n_bins: usize,
    dx: f64,
    channels: Vec<ChannelTable>,
}

/// Checks a data range and bin count; returns (vmin, vmax, Δ). A degenerate
/// range vmin == vmax (constant data) is widened upward so that it has a
/// positive width; f is constant outside the table anyway.
pub(crate) fn check_range(vmin: f64, vmax: f64, n_bins: usize) -> Result<(f64, f64, f64)> {
    for (name, v) in [("vmin", vmin), ("vmax", vmax)] {
        if !(v.is_finite() && v.abs() <= MAX_ABS_VALUE) {
            bail!(
                "table range: {name} must be finite with |{name}| <= {MAX_ABS_VALUE:e} (got {v})"
            );
        }
    }
    if vmin > vmax {
        bail!("table range: vmin must be <= vmax (got {vmin} > {vmax})");
    }
    if n_bins == 0 || n_bins > MAX_BINS {
        bail!("table range: bin count must be in 1..={MAX_BINS} (got {n_bins})");
    }
    let vmax = if vmax > vmin {
        vmax
    } else {
        vmin + f64::max(1.0, vmin.abs() * 1e-6)
    };
    let dx = (vmax - vmin) / n_bins as f64;
    if !(dx > 0.0 && dx.is_finite()) {
        bail!("table range: [{vmin}, {vmax}] is too narrow for {n_bins} bins");
    }
    Ok((vmin, vmax, dx))
}

/// Data value of node i (exactly vmax for i = N).
pub(crate) fn node_position(vmin: f64, vmax: f64, dx: f64, n_bins: usize, i: usize) -> f64 {
    if i >= n_bins {
        vmax
    } else {
        vmin + i as f64 * dx
    }
}

impl PreintTable {
    /// A bin count for data in [vmin, vmax]: bin width 1 for integer data
    /// spanning at most 65536 (every integer data value, and every integer
    /// control value, is then a node), otherwise [`DEFAULT_BINS`].
    pub fn suggested_bins(vmin: f64, vmax: f64, integer_data: bool) -> usize {
        let range = vmax - vmin;
        if integer_data && range.is_finite() && range <= 65536.0 {
            (range.round() as usize).max(1)
        } else {
            DEFAULT_BINS
        }
    }

    /// Builds the table of `tf` over [vmin, vmax] with `n_bins` bins
    /// (1..=[`MAX_BINS`]). Node i is at s_i = vmin + i·Δ, Δ = (vmax−vmin)/N;
    /// vmin == vmax is widened to a positive width.
    pub fn new(tf: &TransferFunction, vmin: f64, vmax: f64, n_bins: usize) -> Result<Self> {
        let (vmin, vmax, dx) = check_range(vmin, vmax, n_bins)?;
        let mut channels: Vec<ChannelTable> = (0..Channel::COUNT)
            .map(|_| ChannelTable {
                nodes: Vec::with_capacity(n_bins + 1),
                mids: Vec::with_capacity(n_bins),
                levels: Vec::new(),
            })
            .collect();
        for i in 0..=n_bins {
            let o = tf.eval(node_position(vmin, vmax, dx, n_bins, i));
            for ch in Channel::ALL {
                channels[ch.index()].nodes.push(ch.of(&o));
            }
        }
        // Bins with a control point strictly inside, and both bins beside a
        // step on a node (the node holds only the step's upper value), stay
        // linear.
        let mut kinked = vec![false; n_bins];
        let points = tf.points();
        for (i, p) in points.iter().enumerate() {
            let u = (p.value - vmin) / dx;
            if !(u > -1.0 && u < n_bins as f64 + 1.0) {
                continue;
            }
            let on_node = (u - u.round()).abs() <= 1e-9 * u.abs().max(1.0);
            let step = points.get(i + 1).is_some_and(|q| q.value == p.value);
            if !on_node {
                if u > 0.0 && u < n_bins as f64 {
                    kinked[u as usize] = true;
                }
            } else if step {
                let k = u.round() as i64;
                for j in [k - 1, k] {
                    if (0..n_bins as i64).contains(&j) {
                        kinked[j as usize] = true;
                    }
                }
            }
        }
        for (j, &kink) in kinked.iter().enumerate() {
            let o = (!kink).then(|| tf.eval(vmin + (j as f64 + 0.5) * dx));
            for ch in Channel::ALL {
                let t = &mut channels[ch.index()];
                let linear = 0.5 * (t.nodes[j] + t.nodes[j + 1]);
                t.mids.push(o.as_ref().map_or(linear, |o| ch.of(o)));
            }
        }
        for table in &mut channels {
            let level0: Vec<f64> = (0..n_bins)
                .map(|j| (table.nodes[j] + 4.0 * table.mids[j] + table.nodes[j + 1]) / 6.0)
                .collect();
            table.levels.push(level0);
            loop {
                let prev = table.levels.last().expect("level 0 exists");
                if prev.len() < 2 {
                    break;
                }
                let next: Vec<f64> = prev.chunks_exact(2).map(|p| p[0] + p[1]).collect();
                table.levels.push(next);
            }
        }
        Ok(PreintTable {
            vmin,
            vmax,
            n_bins,
            dx,
            channels,
        })
    }

    pub fn vmin(&self) -> f64 {
        self.vmin
    }

    pub fn vmax(&self) -> f64 {
        self.vmax
    }

    pub fn n_bins(&self) -> usize {
        self.n_bins
    }

    /// Δ, the bin width in data units.
    pub fn bin_width(&self) -> f64 {
        self.dx
    }

    /// Table coordinate of data value s: u = (s − vmin)/Δ, NaN taken as vmin,
    /// limited to ±1e300 so that lengths stay finite.
    fn to_u(&self, s: f64) -> f64 {
        if s.is_nan() {
            return 0.0;
        }
        ((s - self.vmin) / self.dx).clamp(-1e300, 1e300)
    }

    /// The bin holding u ∈ [0, N] (the last bin for u = N).
    fn bin_of(&self, u: f64) -> usize {
        (u as usize).min(self.n_bins - 1)
    }

    /// f at u ∈ [0, N], the in-bin quadratic.
    fn f_u(&self, ch: &ChannelTable, u: f64) -> f64 {
        let j = self.bin_of(u);
        let t = (u - j as f64).clamp(0.0, 1.0);
        self.bin_avg(ch, j, t, t)
    }

    /// Average of f over [j + ta, j + tb] within bin j.
    fn bin_avg(&self, ch: &ChannelTable, j: usize, ta: f64, tb: f64) -> f64 {
        bin_average(ch.nodes[j], ch.mids[j], ch.nodes[j + 1], ta, tb)
    }

    /// Σ of whole bins [lo, hi) from the pyramid: greedy aligned dyadic
    /// blocks, at most ~2·log₂N terms, every term ≥ 0.
    fn sum_bins(ch: &ChannelTable, mut lo: usize, hi: usize) -> f64 {
        let top = ch.levels.len() - 1;
        let mut sum = 0.0;
        while lo < hi {
            let mut k = if lo == 0 {
                top
            } else {
                (lo.trailing_zeros() as usize).min(top)
            };
            while (1usize << k) > hi - lo {
                k -= 1;
            }
            sum += ch.levels[k][lo >> k];
            lo += 1 << k;
        }
        sum
    }

    /// ∫ f du over [ua, ub] ⊆ [0, N], ua ≤ ub: exact for the in-bin quadratic.
    fn integral_u(&self, ch: &ChannelTable, ua: f64, ub: f64) -> f64 {
        let ja = self.bin_of(ua);
        let first_end = ja + 1;
        let ta = (ua - ja as f64).clamp(0.0, 1.0);
        if ub <= first_end as f64 {
            return (ub - ua) * self.bin_avg(ch, ja, ta, (ub - ja as f64).clamp(0.0, 1.0));
        }
        let jb = (ub as usize).min(self.n_bins);
        let mut sum = (first_end as f64 - ua) * self.bin_avg(ch, ja, ta, 1.0);
        sum += Self::sum_bins(ch, first_end, jb);
        if jb < self.n_bins {
            let tb = (ub - jb as f64).clamp(0.0, 1.0);
            sum += (ub - jb as f64) * self.bin_avg(ch, jb, 0.0, tb);
        }
        sum
    }

    /// The table's f at data value s (linear between nodes, constant outside
    /// [vmin, vmax]).
    pub fn value(&self, channel: Channel, s: f64) -> f64 {
        let u = self.to_u(s).clamp(0.0, self.n_bins as f64);
        self.f_u(&self.channels[channel.index()], u)
    }

    /// The table's f of every channel at data value s, in [`Channel`] order.
    pub fn values(&self, s: f64) -> [f64; Channel::COUNT] {
        let u = self.to_u(s).clamp(0.0, self.n_bins as f64);
        let mut out = [0.0; Channel::COUNT];
        for (o, ch) in out.iter_mut().zip(&self.channels) {
            *o = self.f_u(ch, u);
        }
        out
    }

    /// ∫ₐᵇ f(s) ds in data units, for a ≤ b (the bounds are swapped
    /// otherwise, so the result is always ≥ 0). Outside [vmin, vmax] f is
    /// constant. Never NaN; saturates at f64::MAX.
    pub fn integral(&self, channel: Channel, a: f64, b: f64) -> f64 {
        let ch = &self.channels[channel.index()];
        let (ua, ub) = self.ordered_u(a, b);
        let n = self.n_bins as f64;
        let low = if ua < 0.0 { ub.min(0.0) - ua } else { 0.0 };
        let high = if ub > n { ub - ua.max(n) } else { 0.0 };
        let (ca, cb) = (ua.clamp(0.0, n), ub.clamp(0.0, n));
        let inner = if ca < cb {
            self.integral_u(ch, ca, cb)
        } else {
            0.0
        };
        let mut total = inner;
        if low > 0.0 && ch.nodes[0] > 0.0 {
            total += low * ch.nodes[0];
        }
        if high > 0.0 && ch.nodes[self.n_bins] > 0.0 {
            total += high * ch.nodes[self.n_bins];
        }
        (total * self.dx).min(f64::MAX)
    }

    fn ordered_u(&self, a: f64, b: f64) -> (f64, f64) {
        let (ua, ub) = (self.to_u(a), self.to_u(b));
        if ua <= ub {
            (ua, ub)
        } else {
            (ub, ua)
        }
    }

    /// Segment average f̄ = (1/(b−a))·∫ₐᵇ f(s) ds (G10 §4 Eq. 2), a and b in
    /// either order.
    ///
    /// Eq. 2 returns f(s_i) when |s_i − s_{i−1}| ≤ ε, because there the
    /// difference F(s_i) − F(s_{i−1}) of its running integral is mostly
    /// rounding noise and dividing it by a tiny length amplifies the noise.
    /// Here no threshold is needed: when a and b lie in the same bin, f is
    /// quadratic on [a, b] and the average is exactly f((a+b)/2) + c₂w²/12,
    /// with no division, however close a and b are (a == b gives f(a)). Otherwise the
    /// integral is a sum of non-negative terms with relative error of a few
    /// ulps, and b − a is at least the distance to a bin boundary on each
    /// side, so the quotient keeps full relative precision too.
    pub fn average(&self, channel: Channel, a: f64, b: f64) -> f64 {
        let ch = &self.channels[channel.index()];
        let (ua, ub) = self.ordered_u(a, b);
        let n = self.n_bins as f64;
        if ub <= 0.0 {
            return ch.nodes[0];
        }
        if ua >= n {
            return ch.nodes[self.n_bins];
        }
        if ua >= 0.0 && ub <= n && ub <= (self.bin_of(ua) + 1) as f64 {
            let j = self.bin_of(ua);
            let t = |u: f64| (u - j as f64).clamp(0.0, 1.0);
            return self.bin_avg(ch, j, t(ua), t(ub));
        }
        // Here ua < ub, both finite (|u| ≤ 1e300), so the length is finite.
        let total = ub - ua;
        let (ca, cb) = (ua.max(0.0), ub.min(n));
        let inner = self.integral_u(ch, ca, cb);
        let low = if ua < 0.0 { -ua } else { 0.0 };
        let high = if ub > n { ub - n } else { 0.0 };
        if low == 0.0 && high == 0.0 {
            inner / total
        } else {
            // Weights ≤ 1 keep every product finite.
            (low / total) * ch.nodes[0] + inner / total + (high / total) * ch.nodes[self.n_bins]
        }
    }

    /// Node count along each axis of [`Self::grid`]: the table's nodes where
    /// there are at most 512, else 512 spread evenly over [vmin, vmax].
    pub fn grid_nodes(&self) -> usize {
        self.n_bins.min(511) + 1
    }

    /// The classic 2D pre-integration table (Engel, Kraus and Ertl, "High-
    /// quality pre-integrated volume rendering using hardware-accelerated
    /// pixel shading", 2001) of the DVR channels: with n = [`Self::grid_nodes`]
    /// nodes s_i = vmin + i·(vmax − vmin)/(n − 1), entry i + n·j is the
    /// average of (τ, k̃r, k̃g, k̃b) over the segment from s_i to s_j, exact
    /// (this table's [`Self::average`]) at the nodes; a renderer
    /// interpolates it bilinearly between them.
    pub fn grid(&self) -> Vec<[f32; 4]> {
        let n = self.grid_nodes();
        let s = |i: usize| self.vmin + (self.vmax - self.vmin) * i as f64 / (n - 1) as f64;
        let dvr = [
            Channel::Tau,
            Channel::EmissionR,
            Channel::EmissionG,
            Channel::EmissionB,
        ];
        let mut out = vec![[0f32; 4]; n * n];
        for j in 0..n {
            for i in 0..=j {
                let v: [f32; 4] = std::array::from_fn(|c| self.average(dvr[c], s(i), s(j)) as f32);
                out[i + n * j] = v;
                out[j + n * i] = v;
            }
        }
        out
    }

    /// Averages of every channel over the data-value segment [a, b].
    pub fn segment(&self, a: f64, b: f64) -> SegmentOptics {
        let avg = |c| self.average(c, a, b);
        SegmentOptics {
            tau: avg(Channel::Tau),
            emission: [
                avg(Channel::EmissionR),
                avg(Channel::EmissionG),
                avg(Channel::EmissionB),
            ],
            importance: avg(Channel::Importance),
            refraction: avg(Channel::Refraction),
        }
    }

    /// The node values of a channel (N+1 of them).
    pub fn nodes(&self, channel: Channel) -> &[f64] {
        &self.channels[channel.index()].nodes
    }

    /// Pyramid level k of a channel: N >> k bin integrals in units of bins.
    pub fn level(&self, channel: Channel, k: usize) -> &[f64] {
        &self.channels[channel.index()].levels[k]
    }

    /// Number of pyramid levels.
    pub fn levels(&self) -> usize {
        self.channels[0].levels.len()
    }

    /// The table flattened into one `f32` array for the GPU, with its layout
    /// (see [`PreintLayout`]). Every value is rounded once from f64
    /// (saturating at f32::MAX); all values are ≥ 0, so sums formed from
    /// them in f32 do not cancel either.
    pub fn gpu_layout(&self) -> (Vec<f32>, PreintLayout) {
        let n = self.n_bins;
        let levels = self.levels();
        let mut level_offsets = [0u32; MAX_LEVELS];
        let mut offset = n + 1;
        for (k, slot) in level_offsets.iter_mut().enumerate().take(levels) {
            *slot = offset as u32;
            offset += n >> k;
        }
        let mid_offset = offset as u32;
        let stride = offset + n;
        let mut data = Vec::with_capacity(stride * Channel::COUNT);
        let to_f32 = |x: f64| x.min(f32::MAX as f64) as f32;
        for ch in &self.channels {
            data.extend(ch.nodes.iter().map(|&x| to_f32(x)));
            for level in &ch.levels {
                data.extend(level.iter().map(|&x| to_f32(x)));
            }
            data.extend(ch.mids.iter().map(|&x| to_f32(x)));
        }
        debug_assert_eq!(data.len(), stride * Channel::COUNT);
        let layout = PreintLayout {
            n_bins: n as u32,
            levels: levels as u32,
            channels: Channel::COUNT as u32,
            channel_stride: stride as u32,
            level_offsets,
            mid_offset,
            vmin: self.vmin,
            vmax: self.vmax,
            bin_width: self.dx,
        };
        (data, layout)
    }
}
