//! `probe` (`shaders/enhancers/probe.wgsl`): G10 §4 "Context-preserving
//! probe", Eqs. 4–5.

use super::{
    default_alignment, default_axis, Checker, Enhancer, Field, Needs, PackContext, Rule, REACH_M,
};
use crate::overlay::{circle, Shape};
use anyhow::{bail, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// G10 §4 "Context-preserving probe": a sphere in display space whose
/// enhancer multiplies a sample's opacity by μ(α) and its colour by μ(i)
/// (Eqs. 4–5). With s the sample's distance along the ray from the plane
/// through the centre facing the ray (negative in front), ω_d = 1 − (s/r)²
/// (one on that plane, zero a radius away) and
///   in front (s < 0):  μ(α) = lerp(0, η, ω_d),  μ(i) = 1 − η,
///   behind   (s ≥ 0):  μ(α) = lerp(η, 1, 1 − ω_d),  μ(i) = lerp(1 − η, 1, 1 − ω_d),
/// η = ω_a · smoothstep(g_l, g_h, ι·‖∇s‖/∇_max) · (1 − |∇s·v|/‖∇s‖)⁴,
/// ω_a = smoothstep(a_l, a_h, max(0, −a·v)) for the ray direction v and the
/// probe's axis a (pointing towards the viewers who see its edges). Samples
/// outside the sphere are untouched. G10 writes (1 − ∇s·v/‖∇s‖)⁴ without
/// the absolute value; the gradient's sign says only which side of a
/// surface is denser, so both sides are treated alike here (η stays ≤ 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Probe {
    /// The sphere's centre (m, display space).
    pub center: [f64; 3],
    /// Its radius (m).
    pub radius: f64,
    /// The tool's axis: looking against it, contextual edges show.
    #[serde(default = "default_axis")]
    pub axis: [f64; 3],
    /// a_l, a_h of ω_a, over the cosine between the view and the axis.
    #[serde(default = "default_alignment")]
    pub alignment: [f64; 2],
    /// g_l, g_h of η's gradient filter, over ι·‖∇s‖/∇_max.
    #[serde(default = "default_gradient")]
    pub gradient: [f64; 2],
}

fn default_gradient() -> [f64; 2] {
    [0.02, 0.2]
}

impl Probe {
    /// The sphere's centre and radius in volume space (data length units).
    pub fn in_volume(&self, ctx: &PackContext) -> (DVec3, f64) {
        let k = ctx.placement.scale(ctx.extent);
        (ctx.to_volume(DVec3::from(self.center)), self.radius / k)
    }

    /// A probe at `center` of `radius` with the default axis and filters.
    pub fn new(center: [f64; 3], radius: f64) -> Probe {
        Probe {
            center,
            radius,
            axis: default_axis(),
            alignment: default_alignment(),
            gradient: default_gradient(),
        }
    }
}

impl Enhancer for Probe {
    const NAME: &'static str = "probe";
    const NEEDS: Needs = Needs {
        gradient: true,
        importance: true,
        breaks: true,
        optics: true,
        // μ(α) and μ(i) are at most 1 (Eqs. 4–5).
        ..Needs::NOTHING
    };
    const FIELDS: &'static [Field] = &[
        Field::new("center", "center (m)", 0.001, Rule::Range(-REACH_M, REACH_M)),
        Field::new("radius", "radius (m)", 0.001, Rule::Range(1e-9, REACH_M)),
        Field::new("axis", "axis", 0.1, Rule::Direction),
        Field::new("alignment", "alignment", 0.01, Rule::Ordered(0.0, 1.0)),
        Field::new("gradient", "gradient", 0.01, Rule::Ordered(0.0, 1.0)),
    ];

    fn new_tool(_range: [f64; 2]) -> Self {
        Probe::new([0.0, 0.0, 0.05], 0.04)
    }

    fn pack(&self, ctx: &PackContext) -> [[f32; 4]; 4] {
        let f = |x: f64| x as f32;
        let (centre, r) = self.in_volume(ctx);
        let axis = ctx.direction_to_volume(self.axis);
        [
            [f(centre.x), f(centre.y), f(centre.z), f(r)],
            [
                f(axis.x),
                f(axis.y),
                f(axis.z),
                f(ctx.gradient_max.max(1e-30)),
            ],
            [
                f(self.alignment[0]),
                f(self.alignment[1]),
                f(self.gradient[0]),
                f(self.gradient[1]),
            ],
            [0.0; 4],
        ]
    }

    fn check(&self, c: &Checker) -> Result<()> {
        if !self.center.iter().all(|x| x.is_finite() && x.abs() <= REACH_M) {
            bail!(
                "{}: center must be finite and within {REACH_M} m (got {:?})",
                c.what,
                self.center
            );
        }
        if !(self.radius.is_finite() && self.radius > 0.0 && self.radius <= REACH_M) {
            bail!(
                "{}: radius must be in (0, {REACH_M}] m (got {})",
                c.what,
                self.radius
            );
        }
        c.direction(&self.axis, "axis")?;
        c.unit_pair(&self.alignment, "alignment", "a_l, a_h")?;
        c.unit_pair(&self.gradient, "gradient", "g_l, g_h")
    }

    /// Its centre and radius are bounded by `check`.
    fn bounds(&self, c: &Checker) -> Result<()> {
        c.within_all(&self.axis, -1e3, 1e3, "axis")
    }

    /// Its sphere's bounding box: only the tiles whose rays can meet it
    /// compute the gradient and importance.
    fn region(&self, ctx: &PackContext) -> Option<[[f64; 3]; 2]> {
        let (c, r) = self.in_volume(ctx);
        Some([(c - r).to_array(), (c + r).to_array()])
    }

    /// A sphere that misses the box changes no sample.
    fn acts_on(&self, ctx: &PackContext) -> bool {
        let (c, r) = self.in_volume(ctx);
        let nearest = c.clamp(DVec3::ZERO, DVec3::from(ctx.extent));
        (nearest - c).length() < r
    }

    /// Three great circles of its sphere, labelled at the top.
    fn shapes(&self, _ctx: &PackContext) -> Vec<Shape> {
        let (c, r) = (DVec3::from(self.center), self.radius);
        vec![
            Shape::Polyline(circle(c, r, DVec3::X, DVec3::Y)),
            Shape::Polyline(circle(c, r, DVec3::Y, DVec3::Z)),
            Shape::Polyline(circle(c, r, DVec3::Z, DVec3::X)),
            Shape::Label(c + DVec3::Y * r, "probe".into()),
        ]
    }
}
