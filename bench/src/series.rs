//! Playing a time series (`parallax bench series`): a volume as a moving
//! object, `steps` copies of it shifted along x by 2 voxels a step, each
//! its own database; every step change is followed until the cut has
//! converged again, with the next step read ahead (the renderer's default,
//! `Renderer::prefetch`) and without, in one run (DIR/series.csv).

use crate::measure::{self, write_table};
use anyhow::Result;
use parallax_backend::metric::{as_reference, image_error};
use parallax_backend::render::Renderer;
use parallax_backend::store::{self, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume};
use parallax_common::camera::{Placement, View};
use parallax_common::config::RenderConfig;
use parallax_common::tf::TransferFunction;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Frames a step change is followed for at most.
const MAX_FRAMES: usize = 60;

/// One step change.
#[derive(Clone, Debug)]
pub struct SeriesPoint {
    /// The next step was read ahead while the one before was drawn.
    pub prefetch: bool,
    pub step: usize,
    /// The first frame of the step: its time, and its error against the
    /// step's converged frame (RMSE over premultiplied RGBA).
    pub first_ms: f64,
    pub first_rmse: f64,
    /// Frames, and milliseconds from the change, until the cut has
    /// converged (every wanted brick drawn, nothing in flight).
    pub frames: usize,
    pub ms: f64,
}

/// The series' databases: `volume` shifted by 2 voxels a step along x
/// (the edge voxel repeated), imported with the defaults into
/// `out/series/sNN.pxo`.
pub fn import_series(volume: &Volume, steps: usize, out: &Path) -> Result<Vec<PathBuf>> {
    let dir = out.join("series");
    measure::create_out(&dir)?;
    let [nx, ny, nz] = volume.info.dims;
    (0..steps)
        .map(|t| {
            let shift = 2 * t;
            let data = (0..nx * ny * nz)
                .map(|n| {
                    let (i, rest) = (n % nx, n / nx);
                    volume.data[rest * nx + i.saturating_sub(shift)]
                })
                .collect();
            let step = Volume::new(volume.info.clone(), data);
            let path = dir.join(format!("s{t:02}.pxo"));
            store::import(
                &mut MemorySource::new(&step),
                &path,
                &format!("series step {t}"),
                &ImportOptions::default(),
            )?;
            Ok(path)
        })
        .collect()
}

/// Plays `series` step by step at the default settings, with and without
/// reading ahead, following each change until the cut converges.
pub fn run(
    series: &[PathBuf],
    tf: &TransferFunction,
    placement: &Placement,
    view: &View,
    out: &Path,
) -> Result<Vec<SeriesPoint>> {
    let cfg = RenderConfig::default();
    let mut points = Vec::new();
    let mut n = 0u64;
    for prefetch in [true, false] {
        let mut r = Renderer::new(&series[0], &cfg)?;
        r.set_series(series)?;
        r.set_transfer_function(1, tf)?;
        r.prefetch = prefetch;
        for _ in 0..MAX_FRAMES {
            n += 1;
            if r.frame(n, placement, &[*view], &cfg)?.stats.adequate {
                break;
            }
        }
        for step in 1..series.len() {
            let start = Instant::now();
            r.set_step(step)?;
            let mut first = None;
            let mut frames = 0;
            let last = loop {
                n += 1;
                frames += 1;
                let t = Instant::now();
                let f = r.frame(n, placement, &[*view], &cfg)?;
                let ms = t.elapsed().as_secs_f64() * 1e3;
                if first.is_none() {
                    first = Some((f.images[0].clone(), ms));
                }
                if f.stats.adequate || frames == MAX_FRAMES {
                    break f;
                }
            };
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let (img, first_ms) = first.expect("one frame at least");
            points.push(SeriesPoint {
                prefetch,
                step,
                first_ms,
                first_rmse: image_error(&img, &as_reference(&last.images[0])).rmse,
                frames,
                ms,
            });
        }
    }
    write_table(
        &out.join("series.csv"),
        "prefetch,step,first_ms,first_rmse,frames,ms",
        points.iter().map(|p| {
            format!(
                "{},{},{:.2},{:.4e},{},{:.1}",
                p.prefetch, p.step, p.first_ms, p.first_rmse, p.frames, p.ms
            )
        }),
    )?;
    Ok(points)
}

/// The means per mode, and their ratios.
pub fn print(points: &[SeriesPoint]) {
    let mean = |prefetch: bool, f: fn(&SeriesPoint) -> f64| {
        let v: Vec<f64> = points
            .iter()
            .filter(|p| p.prefetch == prefetch)
            .map(f)
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    for prefetch in [true, false] {
        println!(
            "{}: first frame {:.1} ms, RMSE {:.2e} against the converged step; converged after {:.1} frames, {:.0} ms",
            if prefetch { "next step read ahead" } else { "without reading ahead" },
            mean(prefetch, |p| p.first_ms),
            mean(prefetch, |p| p.first_rmse),
            mean(prefetch, |p| p.frames as f64),
            mean(prefetch, |p| p.ms),
        );
    }
    println!(
        "reading ahead / not: first-frame RMSE {:.2}, time to converge {:.2}",
        mean(true, |p| p.first_rmse) / mean(false, |p| p.first_rmse).max(1e-12),
        mean(true, |p| p.ms) / mean(false, |p| p.ms).max(1e-12)
    );
}
