//! `pass-through` (`shaders/enhancers/pass-through.wgsl`): the default
//! enhancer, which changes nothing and compiles to nothing. A scene may name
//! it to measure what the chain itself costs.

use super::{Enhancer, Needs};
use serde::{Deserialize, Serialize};

/// No parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PassThrough {}

impl Enhancer for PassThrough {
    const NAME: &'static str = "pass-through";
    const NEEDS: Needs = Needs::NOTHING;

    fn new_tool(_range: [f64; 2]) -> Self {
        PassThrough {}
    }
}
