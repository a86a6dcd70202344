//! `exaggerated-shading` (`shaders/enhancers/exaggerated-shading.wgsl`):
//! multilevel shading, G10 §3.

use super::{one, Checker, Enhancer, Field, Needs, PackContext, Rule};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// G10 §3 "exaggerated shading [Rusinkiewicz, Burns and DeCarlo 2006]":
/// with n₀, n₁, n₂ the outward normals −∇s/‖∇s‖ of the leaf, its parent and
/// its grandparent at a sample, l the light (display space, towards the
/// light) and l_i = l − (l·n_i)n_i normalised (the light turned into the
/// plane of the next coarser scale),
///   E = ½ + ½·(k₀·clamp(a·n₀·l₁) + k₁·clamp(a·n₁·l₂) + k_b·clamp(n₂·l)),
/// clamp to [−1, 1], weights k normalised to sum 1 (their Eq. 2: each term
/// shades a scale's detail relative to the next coarser one, lit from the
/// side whatever the surface's orientation; the base term is the coarse
/// shape lit as usual). The shade is ambient + diffuse·E of the scene's
/// material, blended with the plain shade (Phong, or none where the scene
/// is unshaded) by `strength`: 0 is plain shading, bit for bit. The light
/// is fixed in display space, so every viewer of a light field display sees
/// the same shading.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExaggeratedShading {
    /// Blend from the plain shade (0) to exaggerated shading (1).
    #[serde(default = "one")]
    pub strength: f64,
    /// a, how sharply the detail terms switch from dark to light, (0, 1000].
    #[serde(default = "default_contrast")]
    pub contrast: f64,
    /// Towards the light, display space.
    #[serde(default = "default_light")]
    pub light: [f64; 3],
    /// k₀, k₁, k_b: the finest detail, the middle scale, the base shape.
    #[serde(default = "default_weights")]
    pub weights: [f64; 3],
}

fn default_contrast() -> f64 {
    4.0
}

fn default_light() -> [f64; 3] {
    [-0.4, 0.6, 1.0]
}

fn default_weights() -> [f64; 3] {
    [0.3, 0.3, 0.4]
}

impl Default for ExaggeratedShading {
    fn default() -> Self {
        ExaggeratedShading {
            strength: one(),
            contrast: default_contrast(),
            light: default_light(),
            weights: default_weights(),
        }
    }
}

impl Enhancer for ExaggeratedShading {
    const NAME: &'static str = "exaggerated-shading";
    const NEEDS: Needs = Needs {
        gradient: true,
        coarse_gradients: true,
        // It shades segments with extinction only.
        shades: true,
        ..Needs::NOTHING
    };
    const FIELDS: &'static [Field] = &[
        Field::new("strength", "strength", 0.05, Rule::Range(0.0, 1.0)),
        Field::new("contrast", "contrast a", 0.5, Rule::Range(1e-9, 1000.0)),
        Field::new("light", "light", 0.1, Rule::Direction),
        Field::new("weights", "weights k", 0.05, Rule::Range(0.0, 1000.0)),
    ];

    fn new_tool(_range: [f64; 2]) -> Self {
        ExaggeratedShading::default()
    }

    fn pack(&self, ctx: &PackContext) -> [[f32; 4]; 4] {
        let f = |x: f64| x as f32;
        let l = ctx.direction_to_volume(self.light);
        let sum: f64 = self.weights.iter().sum();
        let k = self.weights.map(|w| f(w / sum));
        [
            [f(l.x), f(l.y), f(l.z), f(self.strength)],
            [k[0], k[1], k[2], f(self.contrast)],
            [0.0; 4],
            [0.0; 4],
        ]
    }

    fn check(&self, c: &Checker) -> Result<()> {
        c.within(self.strength, 0.0, 1.0, "strength")?;
        if !(self.contrast.is_finite() && self.contrast > 0.0 && self.contrast <= 1000.0) {
            bail!("{}: contrast must be in (0, 1000] (got {})", c.what, self.contrast);
        }
        c.direction(&self.light, "light")?;
        if !(self.weights.iter().all(|&w| w.is_finite() && (0.0..=1e3).contains(&w))
            && self.weights.iter().sum::<f64>() > 1e-9)
        {
            bail!(
                "{}: weights must be three finite values in [0, 1000], not all 0 (got {:?})",
                c.what,
                self.weights
            );
        }
        Ok(())
    }

    fn bounds(&self, c: &Checker) -> Result<()> {
        c.within_all(&self.light, -1e3, 1e3, "light")
    }

    /// At strength 0 it is plain shading: left out of the kernel.
    fn acts_on(&self, _ctx: &PackContext) -> bool {
        self.strength > 0.0
    }
}
