//! What a tool costs (G10 pays about 10 %): each tool placed where it
//! changes no pixel (its image must equal no tool's, bit for bit) and in
//! place, MImDA at γ = 0 (DVR's image) and at γ = 0.5, refraction with ν = 1
//! (the plain image) and bending, on one transfer function at the user's
//! default settings. Times are medians of rounds run round-robin, forwards
//! then backwards; the samples each kernel takes are counted in a frame of
//! their own, so that what a tool's effect asks for (more samples: a clip
//! plane uncovers the inside) is told apart from the kernel's overhead
//! (time per sample).

use crate::kernels::bending;
use crate::measure::{self, converged, timed_frame, write_table, Shot};
use anyhow::{bail, Result};
use parallax_common::config::{Mode, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use parallax_common::tools::{
    BandPicker, ClipPlane, ExaggeratedShading, Probe, Tool, UnsharpGradient,
};
use std::path::Path;

/// One combination's cost against no tool.
#[derive(Clone, Debug)]
pub struct ToolPoint {
    pub tf: String,
    pub name: &'static str,
    /// Whether its image must equal the base's (placed where it changes
    /// nothing), and whether it does, bit for bit.
    pub neutral: bool,
    pub equal: bool,
    pub render_ms: f64,
    pub samples: u64,
    /// Kernel time and samples against the first combination (no tool).
    pub time_ratio: f64,
    pub sample_ratio: f64,
}

/// A clip plane through the head's middle with a 1 cm emphasis band.
fn plane_in_place() -> Tool {
    Tool::ClipPlane(ClipPlane {
        point: [0.0, 0.0, 0.02],
        normal: [0.0, 0.0, 1.0],
        thickness: 0.01,
        context: [0.3, 0.7],
    })
}

/// The same plane moved 5 m towards the viewers: it misses the volume's
/// box (and is left out of the kernel).
fn plane_away() -> Tool {
    Tool::ClipPlane(ClipPlane {
        point: [0.0, 0.0, 5.0],
        ..match plane_in_place() {
            Tool::ClipPlane(c) => c,
            _ => unreachable!(),
        }
    })
}

/// A plane through the head's middle whose normal points away from every
/// viewer, with no band: the view-dependent factor μ is 1 on every ray, so
/// it cuts nothing, but it stays in the kernel (G10 §4: the context comes
/// back as the view turns).
fn plane_facing_away() -> Tool {
    Tool::ClipPlane(ClipPlane {
        point: [0.0, 0.0, 0.02],
        normal: [0.0, 0.0, -1.0],
        thickness: 0.0,
        context: [0.3, 0.7],
    })
}

/// A band picker looking along the view, its band the middle fifth of the
/// transfer function's values.
fn band_picker(tf: &TransferFunction) -> Tool {
    let p = tf.points();
    let (lo, hi) = (p[0].value, p.last().map_or(p[0].value + 1.0, |q| q.value));
    let at = |u: f64| lo + u * (hi - lo);
    Tool::BandPicker(BandPicker {
        band: [at(0.35), at(0.4), at(0.6), at(0.65)],
        points: None,
        axis: [0.0, 0.0, 1.0],
        alignment: [0.7, 0.95],
    })
}

/// Multilevel shading (G10 §3): the gradient unsharp-masked against the
/// parent level's and exaggerated shading, at `strength` (0: plain shading).
fn multilevel_shading(strength: f64) -> Vec<Tool> {
    vec![
        Tool::UnsharpGradient(UnsharpGradient { strength, level: 1 }),
        Tool::ExaggeratedShading(ExaggeratedShading {
            strength,
            ..Default::default()
        }),
    ]
}

/// Which transfer function a combination renders with.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Tf {
    /// The scene's.
    Scene,
    /// The scene's with refraction indices that bend rays.
    Bent,
    /// The scene's with its extinction times the band picker's trapezoid:
    /// what the band picker shows looking along its axis.
    Band,
}

/// The scene's transfer function with its extinction multiplied by the
/// band picker's trapezoid (zero outside [b₀, b₃]; the ramps sampled at 16
/// points each).
fn band_tf(tf: &TransferFunction, band: [f64; 4]) -> Result<TransferFunction> {
    let trapezoid = |v: f64| {
        if v <= band[0] || v >= band[3] {
            0.0
        } else if v < band[1] {
            (v - band[0]) / (band[1] - band[0])
        } else if v <= band[2] {
            1.0
        } else {
            (band[3] - v) / (band[3] - band[2])
        }
    };
    let p = tf.points();
    let mut values: Vec<f64> = vec![p[0].value, p[p.len() - 1].value];
    values.extend(
        p.iter()
            .map(|q| q.value)
            .filter(|v| *v > band[0] && *v < band[3]),
    );
    for k in 0..=16 {
        let t = k as f64 / 16.0;
        values.push(band[0] + t * (band[1] - band[0]));
        values.push(band[2] + t * (band[3] - band[2]));
    }
    values.sort_by(f64::total_cmp);
    values.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    TransferFunction::from_points(
        values
            .into_iter()
            .map(|v| {
                let o = tf.eval(v);
                ControlPoint {
                    value: v,
                    color: o.color,
                    extinction: o.tau * trapezoid(v),
                    importance: o.importance,
                    refraction: o.refraction,
                }
            })
            .collect(),
    )
}

/// The combinations: their names, tools, settings, whether they must equal
/// the base image, and their transfer function. No tool comes first.
fn combinations(
    cfg: &RenderConfig,
    tf: &TransferFunction,
) -> Vec<(&'static str, Vec<Tool>, RenderConfig, bool, Tf)> {
    let with = |mode, gamma, refraction| RenderConfig {
        mode,
        gamma,
        refraction,
        ..cfg.clone()
    };
    let probe = Tool::Probe(Probe::new([0.0, 0.02, 0.08], 0.05));
    // In the air above the head's right side, within the view.
    let probe_away = Tool::Probe(Probe::new([0.12, 0.1, 0.0], 0.025));
    vec![
        ("no tool", vec![], cfg.clone(), true, Tf::Scene),
        (
            "clip plane, 5 m away",
            vec![plane_away()],
            cfg.clone(),
            true,
            Tf::Scene,
        ),
        (
            "clip plane, facing away",
            vec![plane_facing_away()],
            cfg.clone(),
            true,
            Tf::Scene,
        ),
        (
            "probe, in the air",
            vec![probe_away],
            cfg.clone(),
            true,
            Tf::Scene,
        ),
        (
            "pass-through x3",
            vec![Tool::PassThrough(Default::default()); 3],
            cfg.clone(),
            true,
            Tf::Scene,
        ),
        (
            "multilevel shading, strength 0",
            multilevel_shading(0.0),
            cfg.clone(),
            true,
            Tf::Scene,
        ),
        (
            "MImDA gamma 0",
            vec![],
            with(Mode::Mimda, 0.0, false),
            true,
            Tf::Scene,
        ),
        (
            "refraction, nu = 1",
            vec![],
            with(Mode::Dvr, 0.0, true),
            true,
            Tf::Scene,
        ),
        (
            "clip plane in place",
            vec![plane_in_place()],
            cfg.clone(),
            false,
            Tf::Scene,
        ),
        ("probe in place", vec![probe], cfg.clone(), false, Tf::Scene),
        (
            "band picker",
            vec![band_picker(tf)],
            cfg.clone(),
            false,
            Tf::Scene,
        ),
        // What the band picker shows along its axis, as a transfer
        // function of its own with no tool: the samples its effect asks
        // for, at no tool's price.
        (
            "band's own tf, no tool",
            vec![],
            cfg.clone(),
            false,
            Tf::Band,
        ),
        (
            "multilevel shading",
            multilevel_shading(1.0),
            cfg.clone(),
            false,
            Tf::Scene,
        ),
        (
            "MImDA gamma 0.5",
            vec![],
            with(Mode::Mimda, 0.5, false),
            false,
            Tf::Scene,
        ),
        (
            "refraction, nu 1..1.1",
            vec![],
            with(Mode::Dvr, 0.0, true),
            false,
            Tf::Bent,
        ),
    ]
}

/// Runs the study on `shot` (its transfer function named `tf_name`) at
/// `cfg`, `rounds` timed rounds.
pub fn run(shot: Shot, tf_name: &str, cfg: &RenderConfig, rounds: usize) -> Result<Vec<ToolPoint>> {
    let bent = bending(shot.tf)?;
    let Tool::BandPicker(picker) = band_picker(shot.tf) else {
        unreachable!("a band picker")
    };
    let banded = band_tf(shot.tf, picker.band)?;
    let combos = combinations(cfg, shot.tf);
    let tf_of = |t: Tf| match t {
        Tf::Scene => shot.tf,
        Tf::Bent => &bent,
        Tf::Band => &banded,
    };
    let mut renderers = Vec::new();
    let mut images = Vec::new();
    for (_, tools, c, _, t) in &combos {
        let tf = tf_of(*t);
        let (r, f) = converged(Shot { tf, ..shot }, c, tools, measure::CONVERGE_FRAMES)?;
        images.push(f.images.into_iter().next().unwrap());
        renderers.push(r);
    }
    let rounds = rounds.max(3);
    let mut ms = vec![Vec::new(); combos.len()];
    for round in 0..rounds {
        for i in measure::round_order(round, combos.len()) {
            let (_, _, c, _, t) = &combos[i];
            let tf = tf_of(*t);
            let (f, _) = timed_frame(
                &mut renderers[i],
                200 + round as u64,
                Shot { tf, ..shot },
                c,
            )?;
            ms[i].push(f.stats.render_ms);
        }
    }
    let mut out: Vec<ToolPoint> = Vec::new();
    for (i, (name, _, c, neutral, t)) in combos.iter().enumerate() {
        let tf = tf_of(*t);
        renderers[i].count_samples = true;
        let (f, _) = timed_frame(&mut renderers[i], 1000, Shot { tf, ..shot }, c)?;
        let render_ms = measure::median(&mut ms[i]);
        let samples = f.stats.samples;
        let equal = images[i]
            .iter()
            .zip(&images[0])
            .all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits));
        let base = out.first();
        out.push(ToolPoint {
            tf: tf_name.to_string(),
            name,
            neutral: *neutral,
            equal,
            render_ms,
            samples,
            time_ratio: render_ms / base.map_or(render_ms, |b| b.render_ms),
            sample_ratio: samples as f64 / base.map_or(samples, |b| b.samples).max(1) as f64,
        });
    }
    if let Some(p) = out.iter().find(|p| p.neutral && !p.equal) {
        bail!("{tf_name}: {} changes the image where it must not", p.name);
    }
    Ok(out)
}

pub fn print(points: &[ToolPoint]) {
    for p in points {
        println!(
            "{:>12} {:>28}: {:8.1} ms in the kernel, {:.2}× no tool; samples {:.2}×, time per sample {:.2}×{}",
            p.tf,
            p.name,
            p.render_ms,
            p.time_ratio,
            p.sample_ratio,
            p.time_ratio / p.sample_ratio.max(1e-30),
            if p.neutral {
                " (image equal to no tool's, bit for bit)"
            } else {
                ""
            }
        );
    }
}

pub fn write_csv(path: &Path, points: &[ToolPoint]) -> Result<()> {
    write_table(
        path,
        "tf,combination,neutral,equal,render_ms,samples,time_ratio,sample_ratio,time_per_sample_ratio",
        points.iter().map(|p| {
            format!(
                "{},{},{},{},{:.3},{},{:.4},{:.4},{:.4}",
                p.tf,
                p.name,
                p.neutral,
                p.equal,
                p.render_ms,
                p.samples,
                p.time_ratio,
                p.sample_ratio,
                p.time_ratio / p.sample_ratio.max(1e-30)
            )
        }),
    )
}
