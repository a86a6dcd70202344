//! `gradient-direction` (`shaders/enhancers/gradient-direction.wgsl`), a
//! diagnostic: each pixel shows the gradient of its ray's first sample with
//! extinction, as the chain's earlier enhancers leave it (volume space, its
//! direction's x/y/z as red/green/blue from [−1, 1]), opaque; transparent
//! where the ray meets no extinction.

use super::{Enhancer, Needs};
use serde::{Deserialize, Serialize};

/// No parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GradientDirection {}

impl Enhancer for GradientDirection {
    const NAME: &'static str = "gradient-direction";
    // It shows only rays that meet extinction.
    const NEEDS: Needs = Needs {
        gradient: true,
        ..Needs::NOTHING
    };

    fn new_tool(_range: [f64; 2]) -> Self {
        GradientDirection {}
    }
}
