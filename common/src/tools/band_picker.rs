//! `band-picker` (`shaders/enhancers/band-picker.wgsl`): G10 §4 "Band
//! picker", Fig. 9.

use super::{
    default_alignment, default_axis, Checker, Enhancer, Field, Needs, PackContext, Rule,
    ValueWindow,
};
use crate::overlay::{subdivided, Shape};
use anyhow::{bail, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// G10 §4 "Band picker": a band of data values, the trapezoid of four
/// ordered values b₀ ≤ b₁ ≤ b₂ ≤ b₃ (0 below b₀ and above b₃, 1 on [b₁, b₂]).
/// For a segment whose values span [s_lo, s_hi], w is the trapezoid's
/// largest value on that span; with ω_a = smoothstep(a_l, a_h, max(0,
/// −a·v)) of the ray direction v and the tool's axis a,
///   importance ← lerp(ι, w, ω_a)   (1 in the band, 0 outside: MImDA lets
///                                   the band shine through),
///   opacity    × 1 − ω_a·(1 − w)   (the other bands vanish looking along
///                                   the axis and return looking across).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BandPicker {
    /// b₀ … b₃, data values (ignored where `points` is given).
    #[serde(default)]
    pub band: [f64; 4],
    /// The band taken from the scene's transfer function by index: its
    /// control points i ..= j are the plateau [b₁, b₂], their neighbours
    /// i − 1 and j + 1 the ramps' feet b₀ and b₃ (a peak of the function,
    /// one tissue class, is `[i, i]`). Indices past the function's last
    /// point take the last.
    #[serde(default)]
    pub points: Option<[usize; 2]>,
    /// Looking against it, only the band is seen.
    #[serde(default = "default_axis")]
    pub axis: [f64; 3],
    /// a_l, a_h of ω_a, over the cosine between the view and the axis.
    #[serde(default = "default_alignment")]
    pub alignment: [f64; 2],
}

impl BandPicker {
    /// The band's four data values: `band`, or taken from the values of
    /// the transfer function's control points (`points`).
    pub fn values(&self, tf_values: &[f64]) -> [f64; 4] {
        match self.points {
            Some([i, j]) if !tf_values.is_empty() => {
                let last = tf_values.len() - 1;
                let (i, j) = (i.min(last), j.min(last));
                [
                    tf_values[i.saturating_sub(1)],
                    tf_values[i],
                    tf_values[j],
                    tf_values[(j + 1).min(last)],
                ]
            }
            _ => self.band,
        }
    }
}

impl Enhancer for BandPicker {
    const NAME: &'static str = "band-picker";
    const NEEDS: Needs = Needs {
        // It sets the importance; it does not read it.
        sets_importance: true,
        // Its factor on opacity is at most 1.
        optics: true,
        ..Needs::NOTHING
    };
    const FIELDS: &'static [Field] = &[
        Field::new("band", "band", 1.0, Rule::Ordered(-1e12, 1e12)),
        Field::new("axis", "axis", 0.1, Rule::Direction),
        Field::new("alignment", "alignment", 0.01, Rule::Ordered(0.0, 1.0)),
    ];

    /// The band of the middle fifth of the values, with ramps a twentieth
    /// wide.
    fn new_tool(range: [f64; 2]) -> Self {
        let at = |u: f64| range[0] + u * (range[1] - range[0]);
        BandPicker {
            band: [at(0.35), at(0.4), at(0.6), at(0.65)],
            points: None,
            axis: default_axis(),
            alignment: default_alignment(),
        }
    }

    fn pack(&self, ctx: &PackContext) -> [[f32; 4]; 4] {
        let f = |x: f64| x as f32;
        let axis = ctx.direction_to_volume(self.axis);
        [
            self.band.map(f),
            [f(axis.x), f(axis.y), f(axis.z), 0.0],
            [f(self.alignment[0]), f(self.alignment[1]), 0.0, 0.0],
            [0.0; 4],
        ]
    }

    fn check(&self, c: &Checker) -> Result<()> {
        if let Some([i, j]) = self.points {
            if i > j || j > 4096 {
                bail!(
                    "{}: points must be two control point indices i ≤ j of the transfer function (got {:?})",
                    c.what,
                    [i, j]
                );
            }
        } else {
            let v = self.band;
            if !(v.iter().all(|x| x.is_finite())
                && v[0] <= v[1]
                && v[1] <= v[2]
                && v[2] <= v[3]
                && v[0] < v[3])
            {
                bail!(
                    "{}: band must be four ordered finite data values b0 ≤ b1 ≤ b2 ≤ b3 with b0 < b3 (got {v:?})",
                    c.what
                );
            }
        }
        c.direction(&self.axis, "axis")?;
        c.unit_pair(&self.alignment, "alignment", "a_l, a_h")
    }

    fn bounds(&self, c: &Checker) -> Result<()> {
        c.within_all(&self.axis, -1e3, 1e3, "axis")?;
        c.within_all(&self.band, -1e12, 1e12, "band")
    }

    /// With `points` resolved against the transfer function's values: the
    /// band the kernel and the overlay use.
    fn resolved(&self, tf_values: &[f64]) -> Self {
        BandPicker {
            band: self.values(tf_values),
            ..*self
        }
    }

    /// Its axis through the volume's centre, as long as the volume, labelled
    /// with its plateau at the end it points to.
    fn shapes(&self, ctx: &PackContext) -> Vec<Shape> {
        let p = &ctx.placement;
        let axis = DVec3::from(self.axis).normalize();
        let centre = DVec3::from(p.center);
        let half = 0.5 * p.scale(ctx.extent) * DVec3::from(ctx.extent).max_element();
        let end = centre + axis * half;
        vec![
            Shape::Polyline(subdivided(centre - axis * half, end)),
            Shape::Label(end, format!("band {:.4}-{:.4}", self.band[1], self.band[2])),
        ]
    }

    /// Where ω_a = 1 (−a·v ≥ a_h) a segment whose values all miss [b₀, b₃]
    /// gets opacity × 0 (and importance 0): exactly nothing.
    fn value_window(&self) -> Option<ValueWindow> {
        Some(ValueWindow {
            axis: DVec3::from(self.axis).normalize(),
            cos_full: self.alignment[1],
            range: [self.band[0], self.band[3]],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tools::Tool;

    #[test]
    fn a_band_by_index_takes_the_points_and_their_neighbours() {
        let b = BandPicker {
            band: [0.0; 4],
            points: Some([1, 2]),
            axis: [0.0, 0.0, 1.0],
            alignment: [0.7, 0.95],
        };
        let v = [0.0, 25.0, 75.0, 105.0, 125.0];
        assert_eq!(b.values(&v), [0.0, 25.0, 75.0, 105.0]);
        // At the ends the feet are the end points; past the end, the last.
        let first = BandPicker {
            points: Some([0, 0]),
            ..b
        };
        assert_eq!(first.values(&v), [0.0, 0.0, 0.0, 25.0]);
        let past = BandPicker {
            points: Some([7, 9]),
            ..b
        };
        assert_eq!(past.values(&v), [105.0, 125.0, 125.0, 125.0]);
        let bad = Tool::BandPicker(BandPicker {
            points: Some([3, 1]),
            ..b
        });
        assert!(bad
            .check("s.toml")
            .unwrap_err()
            .to_string()
            .contains("points"));
        // Parsed from a scene without a band.
        let t = Tool::from_table(serde_json::json!({"kind": "band-picker", "points": [3, 3]}), "t")
            .unwrap();
        let Tool::BandPicker(p) = t else {
            panic!("not a band picker")
        };
        assert_eq!(p.values(&v), [75.0, 105.0, 105.0, 125.0]);
    }
}

