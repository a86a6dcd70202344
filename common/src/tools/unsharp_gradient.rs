//! `unsharp-gradient` (`shaders/enhancers/unsharp-gradient.wgsl`):
//! multilevel shading, G10 §3 and Fig. 5.

use super::{one, Checker, Enhancer, Field, Needs, PackContext, Rule};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// G10 §3 "multilevel shading effects, such as … normal unsharp masking":
/// where a segment has extinction, its gradient g becomes
///   g + λ·(g − g_c),
/// g_c the gradient of a coarser level's data at the same point (the
/// leaf's parent for `level` 1, its grandparent for 2; the finer one where
/// that level is not resident). The gradient is linear in the data, so this
/// is the gradient of the unsharp-masked volume s + λ·(s − s_c): detail
/// finer than the coarser level's voxel is amplified by 1 + λ, the shape it
/// sits on is kept. Shading and every later enhancer see the masked
/// gradient. λ = 0 is plain shading, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnsharpGradient {
    /// λ, in [0, 10].
    #[serde(default = "one")]
    pub strength: f64,
    /// How many levels coarser the smooth gradient is: 1 or 2.
    #[serde(default = "one_level")]
    pub level: u32,
}

fn one_level() -> u32 {
    1
}

impl Default for UnsharpGradient {
    fn default() -> Self {
        UnsharpGradient {
            strength: one(),
            level: one_level(),
        }
    }
}

impl Enhancer for UnsharpGradient {
    const NAME: &'static str = "unsharp-gradient";
    const NEEDS: Needs = Needs {
        gradient: true,
        coarse_gradients: true,
        ..Needs::NOTHING
    };
    const FIELDS: &'static [Field] = &[
        Field::new("strength", "strength λ", 0.1, Rule::Range(0.0, 10.0)),
        Field::new("level", "level", 1.0, Rule::Range(1.0, 2.0)),
    ];

    fn new_tool(_range: [f64; 2]) -> Self {
        UnsharpGradient::default()
    }

    fn pack(&self, _ctx: &PackContext) -> [[f32; 4]; 4] {
        [
            [self.strength as f32, self.level as f32, 0.0, 0.0],
            [0.0; 4],
            [0.0; 4],
            [0.0; 4],
        ]
    }

    fn check(&self, c: &Checker) -> Result<()> {
        c.within(self.strength, 0.0, 10.0, "strength")?;
        if !(1..=2).contains(&self.level) {
            bail!("{}: level must be 1 or 2 (got {})", c.what, self.level);
        }
        Ok(())
    }

    /// At strength 0 it is plain shading: left out, it costs nothing (in the
    /// kernel it would read two coarser gradients a shaded segment).
    fn acts_on(&self, _ctx: &PackContext) -> bool {
        self.strength > 0.0
    }
}
