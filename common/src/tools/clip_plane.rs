//! `clip-plane` (`shaders/enhancers/clip-plane.wgsl`): G10 §4 "Clip plane
//! with view-dependent context".

use super::{smoothstep, Checker, Enhancer, Field, Needs, PackContext, Rule, REACH_M};
use crate::camera::Placement;
use crate::overlay::{plane_in_box, subdivided, Shape};
use anyhow::Result;
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// G10 §4 "Clip plane with view-dependent context": on the side the normal
/// points into (δ = n·x + p > 0) a sample's opacity is multiplied by
/// μ = smoothstep(f_l, f_h, 1 − max(0, −n·v)); in the band −thickness < δ < 0
/// opacity and shading go smoothly from the sample's own at δ = −thickness to
/// full opacity and ambient-plus-emission shading at δ = 0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipPlane {
    /// A point on the plane (m, display space).
    pub point: [f64; 3],
    /// Points into the half-space that is cut away (display space).
    pub normal: [f64; 3],
    /// Thickness of the emphasis band behind the plane (m); 0: none.
    #[serde(default)]
    pub thickness: f64,
    /// f_l, f_h of the view-dependent factor.
    #[serde(default = "default_context")]
    pub context: [f64; 2],
}

fn default_context() -> [f64; 2] {
    [0.3, 0.7]
}

impl Enhancer for ClipPlane {
    const NAME: &'static str = "clip-plane";
    const NEEDS: Needs = Needs {
        breaks: true,
        optics: true,
        // The emphasis band blends towards full opacity only where τ̄ > 0.
        ..Needs::NOTHING
    };
    const FIELDS: &'static [Field] = &[
        Field::new("point", "point (m)", 0.001, Rule::Range(-REACH_M, REACH_M)),
        Field::new("normal", "normal", 0.1, Rule::Direction),
        Field::new("thickness", "thickness (m)", 0.001, Rule::Range(0.0, REACH_M)),
        Field::new("context", "context", 0.05, Rule::Ordered(0.0, 1.0)),
    ];

    fn new_tool(_range: [f64; 2]) -> Self {
        ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.0,
            context: default_context(),
        }
    }

    fn pack(&self, ctx: &PackContext) -> [[f32; 4]; 4] {
        let f = |x: f64| x as f32;
        let v = self.in_volume(&ctx.placement, ctx.extent);
        [
            [f(v.normal.x), f(v.normal.y), f(v.normal.z), f(v.offset)],
            [f(v.unit.x), f(v.unit.y), f(v.unit.z), f(self.thickness)],
            [f(self.context[0]), f(self.context[1]), 0.0, 0.0],
            [0.0; 4],
        ]
    }

    fn check(&self, c: &Checker) -> Result<()> {
        c.finite(&self.point, "point")?;
        c.direction(&self.normal, "normal")?;
        if !(self.thickness.is_finite() && self.thickness >= 0.0) {
            anyhow::bail!("{}: thickness must be ≥ 0 (got {})", c.what, self.thickness);
        }
        c.unit_pair(&self.context, "context", "f_l, f_h")
    }

    fn bounds(&self, c: &Checker) -> Result<()> {
        c.within_all(&self.point, -REACH_M, REACH_M, "point")?;
        c.within_all(&self.normal, -1e3, 1e3, "normal")?;
        c.within(self.thickness, 0.0, REACH_M, "thickness")
    }

    /// A plane whose cut-away side and band miss the box changes no ray (its
    /// breaks fall outside the box, where a ray integrates nothing).
    fn acts_on(&self, ctx: &PackContext) -> bool {
        let v = self.in_volume(&ctx.placement, ctx.extent);
        ctx.corners()
            .map(|q| v.normal.dot(q) + v.offset)
            .fold(f64::NEG_INFINITY, f64::max)
            > -self.thickness
    }

    /// Its outline where it cuts the volume's box, labelled at its top left
    /// corner (the label reads rightwards).
    fn shapes(&self, ctx: &PackContext) -> Vec<Shape> {
        let poly = plane_in_box(self, ctx);
        if poly.len() < 3 {
            return Vec::new();
        }
        let mut closed: Vec<DVec3> = Vec::new();
        for i in 0..poly.len() {
            let seg = subdivided(poly[i], poly[(i + 1) % poly.len()]);
            closed.extend(if i == 0 { &seg[..] } else { &seg[1..] });
        }
        let top_y = poly.iter().map(|q| q.y).fold(f64::MIN, f64::max);
        let top = poly
            .iter()
            .copied()
            .filter(|q| q.y >= top_y - 1e-9)
            .fold(DVec3::splat(f64::MAX), |m, q| if q.x < m.x { q } else { m });
        vec![
            Shape::Polyline(closed),
            Shape::Label(top, "clip plane".into()),
        ]
    }
}

/// A plane in volume space (data length units): δ(q) = normal·q + offset is
/// the signed distance in display metres of the display point q maps to;
/// `unit` is the plane's unit normal in volume space (for n·v with a
/// volume-space ray direction v).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumePlane {
    pub normal: DVec3,
    pub offset: f64,
    pub unit: DVec3,
}

impl ClipPlane {
    /// The plane in the volume space of `placement` (a volume point q maps to
    /// x = c + R·k·(q − e/2), so n·x − n·point = (k·Rᵀn)·q + n·(c − point) −
    /// k·(Rᵀn)·e/2).
    pub fn in_volume(&self, placement: &Placement, extent: [f64; 3]) -> VolumePlane {
        let n = DVec3::from(self.normal).normalize();
        let k = placement.scale(extent);
        let unit = placement.rotation().transpose() * n;
        let normal = unit * k;
        let offset = n.dot(DVec3::from(placement.center) - DVec3::from(self.point))
            - normal.dot(DVec3::from(extent) * 0.5);
        VolumePlane {
            normal,
            offset,
            unit,
        }
    }

    /// G10 §4: μ = smoothstep(f_l, f_h, 1 − max(0, −n·v)) for a unit view
    /// direction v (display space), the factor on the cut-away side.
    pub fn context_factor(&self, v: DVec3) -> f64 {
        let n = DVec3::from(self.normal).normalize();
        smoothstep(self.context[0], self.context[1], 1.0 - (-n.dot(v)).max(0.0))
    }
}


#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_in_volume_space_measures_display_distance() {
        let placement = Placement {
            center: [0.1, -0.05, 0.2],
            rotation_deg: [20.0, -35.0, 10.0],
            size: 0.3,
        };
        let ext = [181.0, 217.0, 181.0];
        let plane = ClipPlane {
            point: [0.02, 0.01, 0.15],
            normal: [0.3, -0.2, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        };
        let vp = plane.in_volume(&placement, ext);
        let n = DVec3::from(plane.normal).normalize();
        for q in [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(90.0, 100.0, 10.0),
            DVec3::new(181.0, 3.0, 150.0),
        ] {
            let x = placement.to_display(ext, q);
            let want = n.dot(x - DVec3::from(plane.point));
            let got = vp.normal.dot(q) + vp.offset;
            assert!((want - got).abs() < 1e-12, "{want} {got}");
        }
        // n·v is the same in both spaces.
        let v = DVec3::new(0.2, 0.1, -1.0).normalize();
        let (_, vv) = placement.ray_to_volume(ext, DVec3::ZERO, v);
        assert!((vp.unit.dot(vv) - n.dot(v)).abs() < 1e-12);
    }

    #[test]
    fn context_factor_is_zero_head_on_and_one_parallel() {
        let plane = ClipPlane {
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            thickness: 0.0,
            context: [0.3, 0.7],
        };
        assert_eq!(plane.context_factor(DVec3::new(0.0, 0.0, -1.0)), 0.0);
        assert_eq!(plane.context_factor(DVec3::new(1.0, 0.0, 0.0)), 1.0);
        let mut last = -1.0;
        for deg in 0..=90 {
            let a = (deg as f64).to_radians();
            let mu = plane.context_factor(DVec3::new(a.sin(), 0.0, -a.cos()));
            assert!(mu >= last);
            last = mu;
        }
    }

}
