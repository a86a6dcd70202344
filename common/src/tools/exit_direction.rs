//! `exit-direction` (`shaders/enhancers/exit-direction.wgsl`), a
//! diagnostic: each pixel shows its ray's final direction (volume space,
//! x/y/z as red/green/blue from [−1, 1]), opaque — how refraction is checked
//! against Snell's law.

use super::{Enhancer, Needs};
use serde::{Deserialize, Serialize};

/// No parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExitDirection {}

impl Enhancer for ExitDirection {
    const NAME: &'static str = "exit-direction";
    // Every ray shows its direction, through empty space too.
    const NEEDS: Needs = Needs {
        adds_opacity: true,
        ..Needs::NOTHING
    };

    fn new_tool(_range: [f64; 2]) -> Self {
        ExitDirection {}
    }
}
