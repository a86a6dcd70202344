//! Transfer functions (docs/design.md "Transfer function") and their
//! pre-integration tables (G10 §4 Eq. 2).
//!
//! * [`TransferFunction`]: control points loaded from a TOML file of
//!   `[[point]]` tables, piecewise linear in the raw data value, evaluated
//!   exactly by [`TransferFunction::eval`].
//! * [`PreintTable`]: segment averages f̄ = (1/(b−a))∫ₐᵇ f of τ, k̃ = τ·c, ι
//!   and ν for one integration step (G10 §4 Eq. 2). G10's running integral
//!   F(s) = ∫₀ˢ f loses all precision when F(b) − F(a) is a small difference
//!   of large numbers (τ = 1e-6 after a region with τ = 1e6); the table
//!   instead sums non-negative bin integrals from a dyadic pyramid, so
//!   averages keep full relative precision for any extinction range.
//! * [`alpha`], [`premultiplied_color`]: the step opacity α = 1 − exp(−τ̄·d)
//!   and opacity-weighted colour k̃̄/τ̄·α, stable for tiny and huge τ̄·d.
//! * [`closed::ClosedForm`]: the same averages of τ and k̃ in closed form,
//!   from a few coefficients per piece between control points, for the
//!   kernel's `preintegration = "analytic"`.
//! * [`labels::LabelTable`]: a label volume's colour table (TOML, 3D
//!   Slicer, ITK-SNAP) as a transfer function of steps, one per label.
//! * [`EmptinessTable`]: integer prefix counts that answer "is τ ≡ 0 on
//!   [min, max]?" conservatively, for empty-space skipping.
//!
//! ParaView and 3D Slicer presets are imported by the back end's
//! `data::presets`, beside the other importers.

pub mod closed;
mod empty;
mod function;
pub mod labels;
mod preint;

#[cfg(test)]
mod tests;

pub use empty::EmptinessTable;
pub use function::{
    alpha_to_extinction, srgb_to_linear, ControlPoint, Optics, TransferFunction,
    DEFAULT_IMPORTANCE, DEFAULT_REFRACTION, MAX_ABS_VALUE, MAX_ALPHA, MAX_EXTINCTION,
};
pub use preint::{
    alpha, emission_weight, premultiplied_color, Channel, PreintLayout, PreintTable, SegmentOptics,
    DEFAULT_BINS, G10_EPSILON, MAX_BINS, MAX_LEVELS,
};
