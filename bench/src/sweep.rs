//! `parallax bench sweep`: error against the exact integral beside frame
//! time for a sweep of every quality knob (step size, level of detail,
//! 8-bit bricks, early termination, the pre-integration modes, …), written
//! as CSV, an SVG work–precision plot and the convergence order of each
//! knob; then the cost of each kernel combination ([`crate::kernels`]).

use crate::measure::{
    self, converged, full_detail_step, precise_config, precise_step, timed_frame, write_table, Shot,
};
use anyhow::Result;
use parallax_backend::metric::image_error;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::store::{self, BrickEncoding, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Filter, Interpolation, Preintegration, RenderConfig};
use parallax_common::tf::TransferFunction;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One measured configuration.
#[derive(Clone, Debug)]
pub struct Point {
    pub knob: &'static str,
    pub value: f64,
    pub bricks: &'static str,
    pub frame_ms: f64,
    pub render_ms: f64,
    pub rmse: f64,
    pub max_abs: f64,
    pub psnr: f64,
    pub leaves: u64,
}

pub struct BenchOptions<'a> {
    pub volume: &'a Volume,
    pub tf: &'a TransferFunction,
    pub placement: Placement,
    pub view: View,
    pub out: &'a Path,
    /// Timed frames per configuration (the median is reported; at least 5
    /// rounds for the kernels).
    pub repeats: usize,
    /// Only the kernel combinations (`kernels.csv`), not the knob sweep.
    pub kernels_only: bool,
}

/// One setting of one knob.
struct Setting {
    knob: &'static str,
    value: f64,
    bricks: &'static str,
    cfg: RenderConfig,
}

/// Runs the sweep and writes `bench.csv`, `bench.svg`, `orders.csv` and
/// `kernels.csv` into `out`.
pub fn run(o: &BenchOptions) -> Result<Vec<Point>> {
    measure::create_out(o.out)?;
    let t = Instant::now();
    let reference = reference::render(
        o.volume,
        o.tf,
        &o.placement,
        &o.view,
        Tolerance { abs: 1e-6 },
    );
    eprintln!("reference integral: {:.1} s", t.elapsed().as_secs_f64());
    let dbs = import_both(o)?;
    let base = precise_config();
    let settings = if o.kernels_only {
        Vec::new()
    } else {
        settings(&base)
    };
    let mut points = Vec::new();
    for s in settings {
        let db = &dbs.iter().find(|(n, _)| *n == s.bricks).unwrap().1;
        points.push(measure_setting(o, db, &s, &reference)?);
    }
    if !o.kernels_only {
        write_csv(&o.out.join("bench.csv"), &points)?;
        crate::plot::work_precision(&o.out.join("bench.svg"), &points)?;
        write_orders(&o.out.join("orders.csv"), &points)?;
    }
    let shot = Shot {
        db: &dbs[0].1,
        tf: o.tf,
        placement: &o.placement,
        view: &o.view,
    };
    let kernels = crate::kernels::run(shot, o.repeats, &base, &reference)?;
    crate::kernels::write_csv(&o.out.join("kernels.csv"), &kernels)?;
    Ok(points)
}

/// The volume imported twice into `out/db`: full-precision and 8-bit
/// bricks.
fn import_both(o: &BenchOptions) -> Result<Vec<(&'static str, PathBuf)>> {
    let dbs = o.out.join("db");
    std::fs::create_dir_all(&dbs)?;
    let mut paths = Vec::new();
    for (name, enc) in [
        ("full", BrickEncoding::F32),
        ("8-bit", BrickEncoding::U8Range),
    ] {
        let p = dbs.join(format!("{name}.pxo"));
        store::import(
            &mut MemorySource::new(o.volume),
            &p,
            "bench volume",
            &ImportOptions {
                encoding: enc,
                ..Default::default()
            },
        )?;
        paths.push((name, p));
    }
    Ok(paths)
}

/// Every knob's settings, in the order of the CSV: each knob changes one
/// field of the precise base.
fn settings(base: &RenderConfig) -> Vec<Setting> {
    let mut v = Vec::new();
    let mut add = |knob, bricks, values: &[f64], set: fn(&mut RenderConfig, f64)| {
        for &value in values {
            let mut cfg = base.clone();
            set(&mut cfg, value);
            v.push(Setting {
                knob,
                value,
                bricks,
                cfg,
            });
        }
    };
    let steps = [0.125, 0.25, 0.5, 1.0];
    add(
        "step_factor",
        "full",
        &[0.0625, 0.125, 0.25, 0.5, 1.0, 2.0],
        |c, s| c.step_factor = full_detail_step(s),
    );
    add(
        "accuracy",
        "full",
        &[0.25, 0.5, 1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0, 11.0, 16.0],
        |c, a| {
            c.accuracy = a;
            c.step_factor = precise_step(a);
        },
    );
    add("interpolation_exact", "full", &[1.0], |c, _| {
        c.interpolation = Interpolation::Exact
    });
    // L12's adaptive step (Eq. 3): step_factor 0.5 is λ = t·sin(θ/2).
    // (No sub-pixel step with it: λ is the step.)
    add("adaptive_step", "full", &[0.25, 0.5, 1.0], |c, s| {
        c.step_factor = s;
        c.adaptive_step = true;
    });
    // Multilevel sampling (G10 §4): the accuracy sweep with levels blended.
    add("multilevel", "full", &[0.5, 1.0, 2.0, 4.0], |c, a| {
        c.accuracy = a;
        c.step_factor = precise_step(a);
        c.multilevel = true;
    });
    // Tricubic B-spline filtering (L12 §5.1): the step sweep.
    add("tricubic", "full", &steps, |c, s| {
        c.step_factor = full_detail_step(s);
        c.filter = Filter::Tricubic;
    });
    // The exact table (five reads a segment), which "auto" (the base)
    // leaves for the closed form on a CPU device where the function has one.
    add("preintegration_exact", "full", &steps, |c, s| {
        c.step_factor = full_detail_step(s);
        c.preintegration = Preintegration::Exact;
    });
    // The 2D pre-integration table (one bilinear fetch a segment).
    add("preintegration_2d", "full", &steps, |c, s| {
        c.step_factor = full_detail_step(s);
        c.preintegration = Preintegration::TwoD;
    });
    // The exact integral in closed form (no table read).
    add("preintegration_analytic", "full", &steps, |c, s| {
        c.step_factor = full_detail_step(s);
        c.preintegration = Preintegration::Analytic;
    });
    // The old curve: no empty-space skipping inside bricks.
    add("step_factor_without_macrocells", "full", &steps, |c, s| {
        c.step_factor = full_detail_step(s);
        c.macrocells = false;
    });
    // Opaque-segment refinement at the default accuracy and step: parts
    // 1 (off) to 8 (`RenderConfig::refinement`).
    add("refinement", "full", &[1.0, 2.0, 4.0, 8.0], |c, r| {
        c.accuracy = 1.0;
        c.step_factor = 0.5;
        c.refinement = r as u32;
    });
    // Opaque voxels held to accuracy / 1 (off), / 2 (the default), / 4
    // (`RenderConfig::opaque_detail`), at the default accuracy and step.
    add("opaque_detail", "full", &[1.0, 2.0, 4.0], |c, d| {
        c.accuracy = 1.0;
        c.step_factor = 0.5;
        c.opaque_detail = d;
    });
    add(
        "early_termination",
        "full",
        &[0.9, 0.95, 0.99, 0.995, 0.999],
        |c, e| c.early_termination = e,
    );
    add("step_factor", "8-bit", &steps, |c, s| {
        c.step_factor = full_detail_step(s)
    });
    v
}

/// One setting: converged, then timed over `repeats` frames (medians), the
/// last frame measured against the reference.
fn measure_setting(
    o: &BenchOptions,
    db: &Path,
    s: &Setting,
    reference: &[[f64; 4]],
) -> Result<Point> {
    let shot = Shot {
        db,
        tf: o.tf,
        placement: &o.placement,
        view: &o.view,
    };
    let (mut r, mut last) = converged(shot, &s.cfg, &[], measure::CONVERGE_FRAMES)?;
    let mut frame_ms = Vec::new();
    let mut render_ms = Vec::new();
    for i in 0..o.repeats.max(1) {
        let (f, ms) = timed_frame(&mut r, 100 + i as u64, shot, &s.cfg)?;
        frame_ms.push(ms);
        render_ms.push(f.stats.render_ms);
        last = f;
    }
    let e = image_error(&last.images[0], reference);
    let p = Point {
        knob: s.knob,
        value: s.value,
        bricks: s.bricks,
        frame_ms: measure::median(&mut frame_ms),
        render_ms: measure::median(&mut render_ms),
        rmse: e.rmse,
        max_abs: e.max_abs,
        psnr: e.psnr_db,
        leaves: last.stats.cut_leaves_with_data,
    };
    eprintln!(
        "{:>17} = {:<7} {:>5}: {:8.1} ms/frame, RMSE {:.2e}, max {:.2e}, PSNR {:.1} dB, {} bricks",
        p.knob, p.value, p.bricks, p.frame_ms, p.rmse, p.max_abs, p.psnr, p.leaves
    );
    Ok(p)
}

/// The order at which each knob's error falls: the least-squares slope of
/// ln RMSE against ln h over the knob's points, h the knob's value (step
/// factor, accuracy) or, for early termination, the transmittance 1 − value
/// a ray may stop at. Returns (knob, bricks, order, what h is, points).
pub fn convergence_orders(
    points: &[Point],
) -> Vec<(&'static str, &'static str, f64, &'static str, usize)> {
    let mut series: Vec<(&'static str, &'static str)> = Vec::new();
    for p in points {
        if !series.contains(&(p.knob, p.bricks)) {
            series.push((p.knob, p.bricks));
        }
    }
    series
        .into_iter()
        .filter_map(|(knob, bricks)| {
            let (of, h): (&'static str, fn(f64) -> f64) = if knob == "early_termination" {
                ("1 - value", |v| 1.0 - v)
            } else {
                ("value", |v| v)
            };
            let xy: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| {
                    p.knob == knob && p.bricks == bricks && p.rmse > 0.0 && h(p.value) > 0.0
                })
                .map(|p| (h(p.value).ln(), p.rmse.ln()))
                .collect();
            let order = least_squares_slope(&xy)?;
            Some((knob, bricks, order, of, xy.len()))
        })
        .collect()
}

/// The slope of the least-squares line through `xy` (None for fewer than
/// two distinct x).
fn least_squares_slope(xy: &[(f64, f64)]) -> Option<f64> {
    if xy.len() < 2 {
        return None;
    }
    let n = xy.len() as f64;
    let (mx, my) = xy
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let sxx: f64 = xy.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let sxy: f64 = xy.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// Prints and writes each knob's convergence order.
fn write_orders(path: &Path, points: &[Point]) -> Result<()> {
    let orders = convergence_orders(points);
    for (knob, bricks, order, of, n) in &orders {
        eprintln!("convergence order of {knob} ({bricks} bricks): {order:.2} in {of} ({n} points)");
    }
    write_table(
        path,
        "knob,bricks,order,of,points",
        orders
            .iter()
            .map(|(knob, bricks, order, of, n)| format!("{knob},{bricks},{order:.3},{of},{n}")),
    )
}

fn write_csv(path: &Path, points: &[Point]) -> Result<()> {
    write_table(
        path,
        "knob,value,bricks,frame_ms,render_ms,rmse,max_abs,psnr_db,bricks_in_cut",
        points.iter().map(|p| {
            format!(
                "{},{},{},{:.3},{:.3},{:.6e},{:.6e},{:.2},{}",
                p.knob,
                p.value,
                p.bricks,
                p.frame_ms,
                p.render_ms,
                p.rmse,
                p.max_abs,
                p.psnr,
                p.leaves
            )
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slope_of_a_power_law_is_its_order() {
        let xy: Vec<(f64, f64)> = [0.125f64, 0.25, 0.5, 1.0]
            .iter()
            .map(|h| (h.ln(), (3.0 * h.powi(2)).ln()))
            .collect();
        assert!((least_squares_slope(&xy).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(least_squares_slope(&xy[..1]), None);
        assert_eq!(least_squares_slope(&[(1.0, 2.0), (1.0, 3.0)]), None);
    }

    #[test]
    fn every_knob_changes_the_base() {
        let base = precise_config();
        let s = settings(&base);
        assert_eq!(s.len(), 61);
        // Each setting differs from the base, except the sweep's own base
        // step (0.25) of the plain step knobs.
        let same: Vec<_> = s
            .iter()
            .filter(|x| x.cfg == base)
            .map(|x| (x.knob, x.value, x.bricks))
            .collect();
        assert_eq!(
            same,
            [
                ("step_factor", 0.25, "full"),
                ("step_factor", 0.25, "8-bit")
            ]
        );
    }
}
