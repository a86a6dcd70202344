//! The ray caster's quality knobs and the kernel a frame uses.

use super::params::LayerParams;
use super::{KernelKey, ToolParams};
use parallax_common::config::Preintegration;
use parallax_common::config::MAX_LAYERS;
use parallax_common::tools::MAX_ENHANCERS;

/// Quality knobs of the ray caster, and the kernel a frame uses.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Step length as a fraction of the leaf's voxel size.
    pub step_factor: f32,
    /// Rays stop once their opacity reaches this.
    pub early_termination: f32,
    /// Phong shading from central-difference gradients.
    pub shading: bool,
    /// Stepper and enhancer chain (G10 §5: one kernel per combination).
    pub kernel: KernelKey,
    /// MImDA γ (G10 Eq. 3).
    pub gamma: f32,
    /// Isovalue and surface colour (linear RGB) of the isosurface stepper.
    pub iso: [f32; 4],
    /// Render only this quincunx sub-frame (frame reconstruction, G10 §5).
    pub subframe: Option<u32>,
    /// With `subframe`: reconstruct the other pixels on the GPU before the
    /// read-back (`subframes`), first forgetting the history where
    /// `Some(true)`. `None`: the image comes back with the sub-frame's
    /// pixels alone.
    pub reconstruct: Option<bool>,
    /// Prediction buffer (B10 §4): mode (0 off, 1 full traversal, 2
    /// predicted), local window (data units), κ low, κ high.
    /// Record each pixel's depth in the prediction buffer (the ray
    /// parameter, volume units from the ray's origin, where its opacity
    /// first reaches ½; −1 where it never does; 0 in tiles left out): the
    /// overlay's depth combination (G10 §5).
    pub record_depth: bool,
    pub predict: [f32; 4],
    /// The enhancers' constant parameters, in chain order.
    pub tools: [ToolParams; MAX_ENHANCERS],
    /// Boxes (volume space) where an enhancer reads the gradient or the
    /// importance ([`Tool::region`](parallax_common::tools::Tool::region)):
    /// the tiles whose rays can meet one are flagged for the kernel, and
    /// only there does it compute those inputs.
    pub tool_regions: Vec<[[f64; 3]; 2]>,
    /// Step over empty macrocells (L12 §4.1) where the kernel allows it
    /// (plain DVR: no enhancer, MImDA, refraction or isosurface, which may
    /// act where τ = 0).
    pub macrocells: bool,
    /// Count the samples taken (`Rendered::samples`).
    pub count_samples: bool,
    /// L12's adaptive step (Eq. 3): `step_factor` × 2·t·sin(θ/2), a
    /// fraction of the pixel's footprint at the leaf's distance, instead of
    /// the leaf's voxel.
    pub adaptive_step: bool,
    /// Sub-pixel accuracy (issue 40): `accuracy` where it is below 1, else
    /// 0 (off). Where a leaf of the finest level covers more than that many
    /// pixels, no finer data exists to refine to, so its step shrinks
    /// instead, by accuracy / min(p, 1) (p: its voxel's smallest edge over
    /// the pixel's cone at the leaf's entry), to a quarter at most. Not for
    /// isosurfaces (their sparse steps follow their own rule) nor with
    /// `adaptive_step` (whose step is the footprint's already).
    pub sub_pixel: f32,
    /// Opaque-segment refinement (`RenderConfig::refinement`, R): a
    /// segment of optical depth d above 1, met while the ray's opacity is
    /// below 1 − 1/256, is marched again in ⌈d⌉ parts, at most
    /// [`Self::refine_parts`];
    /// R = 1 is off. The kernel has it compiled in only where the transfer
    /// function and the cut's longest step can make such a segment
    /// ([`super::Raycaster`]'s `kernel`), so that translucent functions
    /// pay nothing.
    pub refinement: u32,
    /// Multilevel sampling (G10 §4, Fig. 5): samples blend the leaf's data
    /// with its parent's and grandparent's as the view's footprint asks,
    /// so a cut that mixes levels shows no seams. `None`: off.
    pub multilevel: Option<Multilevel>,
    /// Tricubic B-spline filtering (L12 §5.1) instead of trilinear.
    pub tricubic: bool,
    /// How segment optics are looked up: the exact table (from the
    /// segments' ends where it allows), the 2D table bilinearly (it must
    /// have been made: [`TfTable::build_grid`]), or in closed form (where
    /// the function has one, [`TfTable::has_closed_form`]; else as "2d").
    pub preintegration: Preintegration,
    /// Run only the 8×8 tiles whose rays can meet data (`tiles`); off,
    /// every tile of every view.
    pub tile_culling: bool,
    /// Fetch each sample one pass of the sample loop ahead (the kernel's
    /// LOOKAHEAD), on pools of float voxels read with the 2D table; the
    /// image is the same bit for bit, off only to show that.
    pub lookahead: bool,
    /// The registered layers' opacity (`table[3]`) and view-dependent
    /// opacity (`axis`, `angles`), as many as `kernel.layers`; their tables'
    /// fields come from the [`super::TfTable`].
    pub layers: [LayerParams; MAX_LAYERS],
}

/// What multilevel sampling needs to know of refinement: the same footprint
/// and accuracy decide which levels a sample blends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Multilevel {
    /// Refinement's accuracy: a voxel is adequate when it projects to at
    /// most this many pixels.
    pub accuracy: f32,
    /// The light field display whose s(z) sizes the η > 0 views' detail:
    /// s0 (m) and tan(Φ/2).
    pub lightfield: Option<(f32, f32)>,
}

impl RenderSettings {
    /// The parts an optically thick segment is marched again in: R up to
    /// `step_factor` 1, fewer as the step grows (R / `step_factor`,
    /// rounded), none (1) from 4R/3 up. At steps longer than the voxel the
    /// error is the field's own between samples, which refining the thick
    /// segments alone buys back at a worse price than a shorter step
    /// (CT-Bone at `step_factor` 2–8: 27 % less error for 31 % more time,
    /// docs/performance.md "Opaque segments").
    pub fn refine_parts(&self) -> u32 {
        let r = self.refinement.max(1) as f32;
        (r / self.step_factor.max(1.0)).round().clamp(1.0, r) as u32
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            step_factor: 0.5,
            early_termination: 0.999,
            shading: false,
            kernel: KernelKey::default(),
            gamma: 0.0,
            iso: [0.0; 4],
            subframe: None,
            reconstruct: None,
            predict: [0.0; 4],
            record_depth: false,
            tools: [ToolParams::default(); MAX_ENHANCERS],
            tool_regions: Vec::new(),
            macrocells: true,
            count_samples: false,
            adaptive_step: false,
            sub_pixel: 0.0,
            refinement: 4,
            multilevel: None,
            tricubic: false,
            preintegration: Preintegration::Exact,
            tile_culling: true,
            lookahead: true,
            layers: [LayerParams::default(); MAX_LAYERS],
        }
    }
}

/// How bricks are interpolated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filtering {
    /// By the texture unit (one sample; weights at the hardware's precision).
    Hardware,
    /// By eight loads with exact f32 weights.
    Exact,
}
