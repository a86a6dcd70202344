//! The studies behind `parallax bench <study>` and the figures of
//! `docs/performance.md`: each renders through the back end's public
//! [`Renderer`](parallax_backend::render::Renderer), measures its images
//! with [`parallax_backend::metric`] (the renderer's tests use the same
//! metric) and writes a CSV into the study's output folder.
//!
//! - [`sweep`]: error against the exact integral beside frame time for every
//!   quality knob (CSV, SVG work–precision plot, convergence orders), and
//!   [`kernels`]: the cost of each kernel combination;
//! - [`tools`]: what each tool and stepper costs, placed where it changes
//!   nothing and in place;
//! - [`codecs`]: ratio and speed of every brick codec;
//! - [`sequence`]: frame reconstruction (G10 §5) and the prediction buffer
//!   (B10 §4) against full rendering along an interaction script;
//! - [`anisotropy`]: the level of detail on thick slices;
//! - [`seams`]: steps at level changes, one level per brick against
//!   multilevel sampling (G10 §4);
//! - [`layers`]: what registered layers cost against the volume alone.
//!
//! [`measure`] holds what they share: the precise base settings, the
//! converge-then-time helper and the CSV writer.

pub mod anisotropy;
pub mod codecs;
pub mod kernels;
pub mod layers;
pub mod measure;
mod plot;
pub mod seams;
pub mod sequence;
pub mod series;
pub mod sweep;
pub mod tools;
