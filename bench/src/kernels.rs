//! The cost of each kernel combination (G10 §5: one kernel per
//! combination of stepper and enhancers), measured where it changes nothing
//! (the pass-through chain, refraction with ν = 1: the image must equal
//! plain DVR's) and where it acts.

use crate::measure::{self, converged, timed_frame, write_table, Shot};
use anyhow::Result;
use parallax_backend::metric::{as_reference, image_error};
use parallax_common::config::{Mode, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use parallax_common::tools::{ClipPlane, Tool};
use std::path::Path;

/// One kernel combination's cost.
#[derive(Clone, Debug)]
pub struct KernelPoint {
    pub name: &'static str,
    pub frame_ms: f64,
    pub render_ms: f64,
    /// Against the plain DVR image of the same settings (0: identical).
    pub diff_from_dvr: f64,
}

/// One combination: its name, tools, settings and transfer function.
type Combination<'a> = (&'static str, Vec<Tool>, RenderConfig, &'a TransferFunction);

/// A clip plane through (x, 0, 0) with an emphasis band.
fn plane(x: f64) -> Tool {
    Tool::ClipPlane(ClipPlane {
        point: [x, 0.0, 0.0],
        normal: [0.3, 0.1, 1.0],
        thickness: 0.004,
        context: [0.3, 0.7],
    })
}

/// `tf` with a refraction index rising from 1 to 1.1 over its range.
pub fn bending(tf: &TransferFunction) -> Result<TransferFunction> {
    let points = tf.points();
    let (lo, hi) = (points[0].value, points.last().unwrap().value);
    TransferFunction::from_points(
        points
            .iter()
            .map(|p| {
                let u = if hi > lo {
                    (p.value - lo) / (hi - lo)
                } else {
                    0.0
                };
                ControlPoint {
                    refraction: 1.0 + 0.1 * u,
                    ..*p
                }
            })
            .collect(),
    )
}

/// The combinations, plain DVR first.
fn combinations<'a>(
    cfg: &RenderConfig,
    tf: &'a TransferFunction,
    bending: &'a TransferFunction,
) -> Vec<Combination<'a>> {
    let refraction = RenderConfig {
        refraction: true,
        ..cfg.clone()
    };
    vec![
        ("dvr, no enhancer", vec![], cfg.clone(), tf),
        (
            "pass-through x3",
            vec![Tool::PassThrough(Default::default()); 3],
            cfg.clone(),
            tf,
        ),
        ("clip plane x1", vec![plane(0.0)], cfg.clone(), tf),
        (
            "clip plane x3",
            vec![plane(-0.02), plane(0.0), plane(0.02)],
            cfg.clone(),
            tf,
        ),
        (
            "mimda gamma 0.5",
            vec![],
            RenderConfig {
                mode: Mode::Mimda,
                gamma: 0.5,
                ..cfg.clone()
            },
            tf,
        ),
        ("refraction, nu = 1", vec![], refraction.clone(), tf),
        ("refraction, nu 1..1.1", vec![], refraction, bending),
    ]
}

/// Frame time of the enhancer chain and the steppers at the sweep's base
/// settings (step 1/2, accuracy 1): no enhancer, the pass-through chain
/// (three), one clip plane, three chained, MImDA, refraction (ν = 1: the
/// kernel alone; ν rising with the data: rays bend). The combinations are
/// timed round-robin, forwards then backwards, so that a change in the
/// machine's load falls on all of them alike.
pub fn run(
    shot: Shot,
    repeats: usize,
    base: &RenderConfig,
    reference: &[[f64; 4]],
) -> Result<Vec<KernelPoint>> {
    let cfg = RenderConfig {
        step_factor: 0.5,
        accuracy: 1.0,
        ..base.clone()
    };
    let bent = bending(shot.tf)?;
    let combos = combinations(&cfg, shot.tf, &bent);
    let mut renderers = Vec::new();
    let mut first = Vec::new();
    for (_, tools, c, tf) in &combos {
        let (r, f) = converged(Shot { tf, ..shot }, c, tools, measure::CONVERGE_FRAMES)?;
        first.push(f.images.into_iter().next().unwrap());
        renderers.push(r);
    }
    let rounds = repeats.max(5);
    let mut frame_ms = vec![Vec::new(); combos.len()];
    let mut render_ms = vec![Vec::new(); combos.len()];
    for round in 0..rounds {
        for i in measure::round_order(round, combos.len()) {
            let (_, _, c, tf) = &combos[i];
            let (f, ms) = timed_frame(
                &mut renderers[i],
                200 + round as u64,
                Shot { tf, ..shot },
                c,
            )?;
            frame_ms[i].push(ms);
            render_ms[i].push(f.stats.render_ms);
        }
    }
    let dvr = as_reference(&first[0]);
    eprintln!(
        "kernels (RMSE of plain DVR against the exact integral {:.2e}):",
        image_error(&first[0], reference).rmse
    );
    let mut out: Vec<KernelPoint> = Vec::new();
    for (i, (name, ..)) in combos.iter().enumerate() {
        let p = KernelPoint {
            name,
            frame_ms: measure::median(&mut frame_ms[i]),
            render_ms: measure::median(&mut render_ms[i]),
            diff_from_dvr: image_error(&first[i], &dvr).rmse,
        };
        eprintln!(
            "{:>22}: {:8.1} ms/frame ({:8.1} ms in the kernel), {:.2}× plain DVR, differs from it by RMSE {:.2e}",
            p.name,
            p.frame_ms,
            p.render_ms,
            p.render_ms / out.first().map_or(p.render_ms, |q| q.render_ms),
            p.diff_from_dvr
        );
        out.push(p);
    }
    Ok(out)
}

/// Writes `kernels.csv`: each combination's times and its ratio to plain
/// DVR's kernel time.
pub fn write_csv(path: &Path, points: &[KernelPoint]) -> Result<()> {
    let base = points.first().map_or(1.0, |p| p.render_ms);
    write_table(
        path,
        "kernel,frame_ms,render_ms,ratio_to_dvr,rmse_vs_dvr",
        points.iter().map(|p| {
            format!(
                "{},{:.3},{:.3},{:.3},{:.6e}",
                p.name,
                p.frame_ms,
                p.render_ms,
                p.render_ms / base,
                p.diff_from_dvr
            )
        }),
    )
}
