//! What the studies share: the precise base settings, a renderer whose cut
//! has converged, a timed frame, the median, and CSV tables.

use anyhow::{Context, Result};
use parallax_backend::render::{Frame, Renderer};
use parallax_common::atomic::AtomicFile;
use parallax_common::camera::{Placement, View};
use parallax_common::config::{RenderConfig, Shading};
use parallax_common::tf::TransferFunction;
use parallax_common::tools::Tool;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// The base's accuracy: the finest level everywhere. Being below 1
/// (sub-pixel accuracy), it also takes a quarter of `step_factor` there
/// (the kernel's `leaf_step`, wherever a voxel covers more than 0.04
/// pixels), so a study's step is set through [`full_detail_step`].
pub const FULL_DETAIL: f64 = 0.01;

/// The `step_factor` that samples the finest level every `s` voxels at
/// [`FULL_DETAIL`].
pub fn full_detail_step(s: f64) -> f64 {
    4.0 * s
}

/// The base's step, 1/4 of a voxel, as `step_factor` at `accuracy`: at
/// [`FULL_DETAIL`] through [`full_detail_step`]; at any other accuracy 1/4
/// itself (below 1 sub-pixel accuracy shrinks it further at the finest
/// level: that is the knob's own doing).
pub fn precise_step(accuracy: f64) -> f64 {
    if accuracy == FULL_DETAIL {
        full_detail_step(0.25)
    } else {
        0.25
    }
}

/// Frames a study's renderer may take to converge its cut.
pub const CONVERGE_FRAMES: usize = 64;

/// The studies' base: every knob precise (full detail, step 1/4, rays to
/// the end, no visibility culling, no shading: the reference integral's
/// optics), caches large enough for any test volume.
pub fn precise_config() -> RenderConfig {
    RenderConfig {
        accuracy: FULL_DETAIL,
        step_factor: precise_step(FULL_DETAIL),
        early_termination: 1.0,
        visibility_feedback: false,
        shading: Shading::None,
        cpu_cache_mb: 2048.0,
        gpu_cache_mb: 1024.0,
        upload_budget: 100_000,
        ..RenderConfig::default()
    }
}

/// What a study renders: a database seen by views from one placement.
#[derive(Clone, Copy)]
pub struct Shot<'a> {
    pub db: &'a Path,
    pub tf: &'a TransferFunction,
    pub placement: &'a Placement,
    pub view: &'a View,
}

/// A renderer of `shot` with `cfg` and `tools` whose cut has converged
/// (at most `frames` frames), and the last frame of the convergence.
pub fn converged(
    shot: Shot,
    cfg: &RenderConfig,
    tools: &[Tool],
    frames: usize,
) -> Result<(Renderer, Frame)> {
    let mut r = Renderer::new(shot.db, cfg)?;
    r.set_transfer_function(1, shot.tf)?;
    if !tools.is_empty() {
        r.set_tools(1, tools)?;
    }
    let f = r.converge(shot.placement, &[*shot.view], cfg, frames)?;
    Ok((r, f))
}

/// One frame numbered `n` of `shot` and its wall time (ms).
pub fn timed_frame(
    r: &mut Renderer,
    n: u64,
    shot: Shot,
    cfg: &RenderConfig,
) -> Result<(Frame, f64)> {
    let t = Instant::now();
    let f = r.frame(n, shot.placement, &[*shot.view], cfg)?;
    Ok((f, t.elapsed().as_secs_f64() * 1e3))
}

/// A frame of `shot` once the cut has converged, and its wall time (ms).
pub fn converged_frame(shot: Shot, cfg: &RenderConfig) -> Result<(Frame, f64)> {
    let (mut r, _) = converged(shot, cfg, &[], CONVERGE_FRAMES)?;
    timed_frame(&mut r, 100, shot, cfg)
}

/// The order of round `round` over `n` combinations timed round-robin:
/// forwards, then backwards, so that a change in the machine's load falls
/// on all of them alike.
pub fn round_order(round: usize, n: usize) -> Vec<usize> {
    if round.is_multiple_of(2) {
        (0..n).collect()
    } else {
        (0..n).rev().collect()
    }
}

/// The median (the upper one of an even count); `v` is sorted.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Creates a study's output folder.
pub fn create_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))
}

/// Writes a CSV file (atomically): the header line, then one line a row.
pub fn write_table(
    path: &Path,
    header: &str,
    rows: impl IntoIterator<Item = String>,
) -> Result<()> {
    let mut f = AtomicFile::create(path)?;
    writeln!(f, "{header}")?;
    for r in rows {
        writeln!(f, "{r}")?;
    }
    f.commit()
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 3.0);
    }
}
