//! The transfer function itself: control points, TOML loading and validation,
//! exact evaluation (docs/design.md "Transfer function", G10 §4).

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

/// Largest accepted extinction, per data length unit. Anything near it is
/// opaque over any path longer than 1e-28 units; the cap keeps every integral
/// the pre-integration table forms finite in f64 and in f32.
pub const MAX_EXTINCTION: f64 = 1e30;

/// Largest accepted |value| of a control point. Data values are `f32`, whose
/// magnitude never exceeds 3.4e38; the cap keeps differences of values finite.
pub const MAX_ABS_VALUE: f64 = 1e100;

/// Default importance ι of a control point (G10 §4: ι ∈ ]0,1[).
pub const DEFAULT_IMPORTANCE: f64 = 0.5;

/// Default refraction index ν of a control point (G10 §4: ν ∈ ]0,∞[).
pub const DEFAULT_REFRACTION: f64 = 1.0;

/// One control point: the optical properties at one raw data value.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ControlPoint {
    /// Raw data value (e.g. Hounsfield units for CT).
    pub value: f64,
    /// Linear RGB, each component in [0, 1].
    pub color: [f64; 3],
    /// Extinction τ ≥ 0 per data length unit.
    pub extinction: f64,
    /// Importance ι in the open interval (0, 1), used by MImDA (G10 Eq. 3).
    pub importance: f64,
    /// Refraction index ν > 0.
    pub refraction: f64,
}

impl ControlPoint {
    /// A point with the default importance (0.5) and refraction (1).
    pub fn new(value: f64, color: [f64; 3], extinction: f64) -> Self {
        ControlPoint {
            value,
            color,
            extinction,
            importance: DEFAULT_IMPORTANCE,
            refraction: DEFAULT_REFRACTION,
        }
    }

    pub fn with_importance(mut self, importance: f64) -> Self {
        self.importance = importance;
        self
    }

    pub fn with_refraction(mut self, refraction: f64) -> Self {
        self.refraction = refraction;
        self
    }
}

/// The optical properties at one data value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// Extinction τ per data length unit.
    pub tau: f64,
    /// Linear RGB colour c.
    pub color: [f64; 3],
    /// Extinction-weighted colour k̃ = τ·c (G10 §4).
    pub emission: [f64; 3],
    /// Importance ι.
    pub importance: f64,
    /// Refraction index ν.
    pub refraction: f64,
}

/// A transfer function: piecewise linear in the data value between control
/// points, constant beyond the first and the last point.
///
/// τ, c, ι and ν are interpolated linearly; the emission k̃ = τ·c is formed
/// after interpolation, so it is piecewise quadratic (G10 §4 works with
/// extinction-weighted colours).
///
/// Control points must be listed in non-decreasing value order; an unsorted
/// list is rejected rather than sorted, because the order of points that share
/// a value (a step) is meaningful and a misordered file is most likely a typo.
/// Two points with the same value make a step: for `s >= value` the later
/// point applies.
///
/// Deserializing with serde (e.g. a transfer function embedded in another
/// file) validates too; [`TransferFunction::load`] and
/// [`TransferFunction::from_toml_str`] additionally put the file name in
/// every error message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawFile", into = "RawFile")]
pub struct TransferFunction {
    #[serde(rename = "point")]
    points: Vec<ControlPoint>,
}

/// The TOML file as written: every field optional so that validation can name
/// what is missing, and where.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    point: Vec<RawPoint>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPoint {
    value: Option<f64>,
    color: Option<Vec<f64>>,
    extinction: Option<f64>,
    importance: Option<f64>,
    refraction: Option<f64>,
}

/// Serialised through the same shape it is read from, so that a transfer
/// function written by serde (TOML, or bincode between processes) reads back.
impl From<TransferFunction> for RawFile {
    fn from(tf: TransferFunction) -> Self {
        RawFile {
            point: tf
                .points
                .into_iter()
                .map(|p| RawPoint {
                    value: Some(p.value),
                    color: Some(p.color.to_vec()),
                    extinction: Some(p.extinction),
                    importance: Some(p.importance),
                    refraction: Some(p.refraction),
                })
                .collect(),
        }
    }
}

impl TryFrom<RawFile> for TransferFunction {
    type Error = anyhow::Error;

    fn try_from(raw: RawFile) -> Result<Self> {
        TransferFunction::from_raw(raw, "transfer function")
    }
}

impl TransferFunction {
    /// Loads and validates a TOML file of `[[point]]` tables. Every error
    /// message starts with the file name.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read transfer function", path.display()))?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and validates TOML text; `origin_name` (usually the file name)
    /// starts every error message, e.g.
    /// `tf.toml: point 3: extinction must be finite and >= 0 (got -1)`.
    /// Points are numbered from 1 in file order.
    pub fn from_toml_str(text: &str, origin_name: &str) -> Result<Self> {
        let raw: RawFile = match toml::from_str(text) {
            Ok(raw) => raw,
            Err(e) => bail!("{origin_name}: {}", e.to_string().trim_end()),
        };
        Self::from_raw(raw, origin_name)
    }

    /// Builds a transfer function from control points, with the same
    /// validation as a file (errors name the origin `points`).
    pub fn from_points(points: Vec<ControlPoint>) -> Result<Self> {
        Self::validated(points, "points")
    }

    fn from_raw(raw: RawFile, origin: &str) -> Result<Self> {
        let mut points = Vec::with_capacity(raw.point.len());
        for (i, p) in raw.point.into_iter().enumerate() {
            let n = i + 1;
            let value = p
                .value
                .with_context(|| format!("{origin}: point {n}: missing field `value`"))?;
            let color = p
                .color
                .with_context(|| format!("{origin}: point {n}: missing field `color`"))?;
            if color.len() != 3 {
                bail!(
                    "{origin}: point {n}: color must have 3 components [r, g, b] (got {})",
                    color.len()
                );
            }
            let extinction = p
                .extinction
                .with_context(|| format!("{origin}: point {n}: missing field `extinction`"))?;
            points.push(ControlPoint {
                value,
                color: [color[0], color[1], color[2]],
                extinction,
                importance: p.importance.unwrap_or(DEFAULT_IMPORTANCE),
                refraction: p.refraction.unwrap_or(DEFAULT_REFRACTION),
            });
        }
        Self::validated(points, origin)
    }

    fn validated(points: Vec<ControlPoint>, origin: &str) -> Result<Self> {
        if points.is_empty() {
            bail!("{origin}: no [[point]] tables: a transfer function needs at least one point");
        }
        for (i, p) in points.iter().enumerate() {
            let n = i + 1;
            if !(p.value.is_finite() && p.value.abs() <= MAX_ABS_VALUE) {
                bail!(
                    "{origin}: point {n}: value must be finite with |value| <= {MAX_ABS_VALUE:e} (got {})",
                    p.value
                );
            }
            for (k, &c) in p.color.iter().enumerate() {
                if !(0.0..=1.0).contains(&c) {
                    bail!("{origin}: point {n}: color[{k}] must be finite and in [0, 1] (got {c})");
                }
            }
            if !(p.extinction >= 0.0 && p.extinction.is_finite()) {
                bail!(
                    "{origin}: point {n}: extinction must be finite and >= 0 (got {})",
                    p.extinction
                );
            }
            if p.extinction > MAX_EXTINCTION {
                bail!(
                    "{origin}: point {n}: extinction must be <= {MAX_EXTINCTION:e} (got {})",
                    p.extinction
                );
            }
            if !(p.importance > 0.0 && p.importance < 1.0) {
                bail!(
                    "{origin}: point {n}: importance must be finite and in (0, 1) (got {})",
                    p.importance
                );
            }
            if !(p.refraction > 0.0 && p.refraction.is_finite()) {
                bail!(
                    "{origin}: point {n}: refraction must be finite and > 0 (got {})",
                    p.refraction
                );
            }
            if i > 0 && p.value < points[i - 1].value {
                bail!(
                    "{origin}: point {n}: value must be >= the previous point's value \
                     (got {} after {}); list points in increasing value order",
                    p.value,
                    points[i - 1].value
                );
            }
        }
        Ok(TransferFunction { points })
    }

    /// The control points, in non-decreasing value order.
    pub fn points(&self) -> &[ControlPoint] {
        &self.points
    }

    /// The sorted control values: the only places where the transfer function
    /// has kinks or steps (an exact integrator splits rays there). A step
    /// appears once per point, so values may repeat.
    pub fn control_values(&self) -> Vec<f64> {
        self.points.iter().map(|p| p.value).collect()
    }

    /// The largest importance anywhere (importance is piecewise linear, so
    /// its maximum is at a control point).
    /// The same function with |ν − 1| added to the extinction of every
    /// control point: what a refracting kernel must not skip (a range is
    /// empty under it only where τ = 0 and ν = 1 throughout, since both are
    /// linear between control points).
    pub fn refraction_as_extinction(&self) -> TransferFunction {
        let mut t = self.clone();
        for p in &mut t.points {
            p.extinction += (p.refraction - 1.0).abs();
        }
        t
    }

    /// The same function with every extinction times `k` ≥ 0 (the colours
    /// kept, so the emission k̃ = τ·c scales with it): a layer's share of
    /// a medium.
    pub fn scaled_extinction(&self, k: f64) -> TransferFunction {
        let mut t = self.clone();
        for p in &mut t.points {
            p.extinction *= k.max(0.0);
        }
        t
    }

    pub fn max_importance(&self) -> f64 {
        self.points.iter().map(|p| p.importance).fold(0.0, f64::max)
    }

    /// The largest extinction anywhere.
    pub fn max_extinction(&self) -> f64 {
        self.points.iter().map(|p| p.extinction).fold(0.0, f64::max)
    }

    /// The largest extinction over the values [lo, hi] (0 for an empty or
    /// NaN range): the larger end, or a control point inside. Between
    /// points τ is linear, so its maximum is at one of these.
    pub fn max_extinction_in(&self, lo: f64, hi: f64) -> f64 {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return 0.0;
        }
        let pts = &self.points;
        let first = pts.partition_point(|p| p.value < lo);
        let inside = pts[first..]
            .iter()
            .take_while(|p| p.value <= hi)
            .map(|p| p.extinction);
        inside.fold(self.tau(lo).max(self.tau(hi)), f64::max)
    }

    /// The optical properties at data value `s`. Between control points every
    /// property is linear in `s`; beyond the first and the last point it is
    /// constant; at a step the later point applies for `s >= value`. A NaN `s`
    /// is treated as −∞ (the first point).
    pub fn eval(&self, s: f64) -> Optics {
        let pts = &self.points;
        // Number of points with value <= s (false for NaN).
        let i = pts.partition_point(|p| p.value <= s);
        if i == 0 {
            return optics_of(&pts[0]);
        }
        if i == pts.len() {
            return optics_of(&pts[pts.len() - 1]);
        }
        let (p0, p1) = (&pts[i - 1], &pts[i]);
        // p0.value <= s < p1.value, so the denominator is > 0 (and finite,
        // since |value| <= MAX_ABS_VALUE).
        let t = ((s - p0.value) / (p1.value - p0.value)).clamp(0.0, 1.0);
        // (1−t)·a + t·b of non-negative a, b is non-negative and exact at
        // t = 0 and t = 1.
        let lerp = |a: f64, b: f64| (1.0 - t) * a + t * b;
        let tau = lerp(p0.extinction, p1.extinction);
        let color = [
            lerp(p0.color[0], p1.color[0]),
            lerp(p0.color[1], p1.color[1]),
            lerp(p0.color[2], p1.color[2]),
        ];
        Optics {
            tau,
            color,
            emission: [tau * color[0], tau * color[1], tau * color[2]],
            importance: lerp(p0.importance, p1.importance),
            refraction: lerp(p0.refraction, p1.refraction),
        }
    }

    /// Extinction at `s` (the `tau` of [`TransferFunction::eval`]).
    pub fn tau(&self, s: f64) -> f64 {
        self.eval(s).tau
    }
}

fn optics_of(p: &ControlPoint) -> Optics {
    Optics {
        tau: p.extinction,
        color: p.color,
        emission: [
            p.extinction * p.color[0],
            p.extinction * p.color[1],
            p.extinction * p.color[2],
        ],
        importance: p.importance,
        refraction: p.refraction,
    }
}

/// Largest opacity converted to an extinction: α = 1 (fully opaque within one
/// unit distance) becomes τ = −ln(10⁻⁶)/u ≈ 13.8/u instead of infinity.
pub const MAX_ALPHA: f64 = 1.0 - 1e-6;

/// Extinction τ for a VTK opacity α per `unit` length (`unit` > 0):
/// −ln(1 − α)/unit, α clamped to [0, [`MAX_ALPHA`]] (so finite and ≥ 0; a
/// NaN α gives 0).
pub fn alpha_to_extinction(alpha: f64, unit: f64) -> f64 {
    let a = alpha.clamp(0.0, MAX_ALPHA);
    let tau = -(-a).ln_1p() / unit;
    if tau > 0.0 {
        tau
    } else {
        0.0
    }
}

/// The sRGB decoding curve (IEC 61966-2-1): display value → linear, [0, 1].
pub fn srgb_to_linear(c: f64) -> f64 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}
