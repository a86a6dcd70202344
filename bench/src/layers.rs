//! What registered layers cost (`[[layer]]`, G10 §4): a volume with one or
//! two layers on its grid, or one on another grid placed by a transform,
//! against the volume alone, at the user's default
//! settings. The layers are the volume itself, so that the media are the
//! same whatever the count: with n layers, each of the n + 1 media takes
//! 1/(n + 1) of the function's extinction, and the image is the volume's
//! (checked: the RMSE against it). A layer whose function is empty must
//! leave the image bit for bit and cost nothing. Under MImDA (γ = 0.8) the
//! two media are measured against the volume alone under MImDA. Times are
//! medians of rounds run round-robin, forwards then backwards.

use crate::measure::{self, timed_frame, write_table, Shot};
use anyhow::Result;
use parallax_backend::gpu::AdapterRequest;
use parallax_backend::render::Renderer;
use parallax_common::config::{Layer, LayerTransform, Mode, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::{Path, PathBuf};

/// One case against the volume alone.
#[derive(Clone, Debug)]
pub struct LayerPoint {
    pub name: &'static str,
    /// The case it is measured against (the volume alone, under the same
    /// stepper).
    pub against: &'static str,
    /// Layers the renderer draws (an empty one is left out).
    pub drawn: usize,
    pub render_ms: f64,
    pub time_ratio: f64,
    /// RMSE against the volume alone's image, and whether it equals it
    /// bit for bit.
    pub rmse: f64,
    pub equal: bool,
    /// From a cold renderer to the converged frame (reads, uploads and
    /// frames; a placed layer's resampling is in it), and the bytes read.
    pub converge_ms: f64,
    pub bytes_read: u64,
}

/// Writes `tf` into `dir` as `name` and returns the path.
fn write_tf(dir: &Path, name: &str, tf: &TransferFunction) -> Result<PathBuf> {
    let p = dir.join(name);
    std::fs::write(&p, toml::to_string(tf)?)?;
    Ok(p)
}

/// Runs the study on `shot` at `cfg` (`out` holds the layers' transfer
/// functions), `rounds` timed rounds; `other_grid` is the volume on other
/// bricks, the layer that a transform places (the identity: its voxel
/// centres are the volume's, so the image stays the volume's).
pub fn run(
    shot: Shot,
    other_grid: &Path,
    cfg: &RenderConfig,
    rounds: usize,
    out: &Path,
) -> Result<Vec<LayerPoint>> {
    let layer = |tf: PathBuf| Layer {
        volume: shot.db.to_path_buf(),
        transfer_function: Some(tf),
        labels: None,
        opacity: 1.0,
        visible: true,
        view_opacity: None,
        transform: None,
    };
    let placed = |tf: PathBuf| Layer {
        volume: other_grid.to_path_buf(),
        transform: Some(LayerTransform::Matrix(vec![
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ])),
        ..layer(tf)
    };
    let p = shot.tf.points();
    let top = p.last().map_or(1.0, |q| q.value);
    let empty = TransferFunction::from_points(vec![
        ControlPoint::new(top + 1.0, [1.0, 0.0, 0.0], 0.0),
        ControlPoint::new(top + 2.0, [1.0, 0.0, 0.0], 1.0),
    ])?;
    let empty = write_tf(out, "layers-empty.toml", &empty)?;
    let half = shot.tf.scaled_extinction(0.5);
    let third = shot.tf.scaled_extinction(1.0 / 3.0);
    let half_file = write_tf(out, "layers-half.toml", &half)?;
    let third_file = write_tf(out, "layers-third.toml", &third)?;
    let mimda = RenderConfig {
        mode: Mode::Mimda,
        gamma: 0.8,
        ..cfg.clone()
    };
    // (name, function, layers, settings, the case it is measured against)
    type Case<'a> = (
        &'static str,
        &'a TransferFunction,
        Vec<Layer>,
        &'a RenderConfig,
        usize,
    );
    let cases: Vec<Case> = vec![
        ("the volume alone", shot.tf, vec![], cfg, 0),
        ("an empty layer", shot.tf, vec![layer(empty)], cfg, 0),
        (
            "2 aligned media (1 layer), 1/2 each",
            &half,
            vec![layer(half_file.clone())],
            cfg,
            0,
        ),
        (
            "2 unaligned media (1 layer on bricks of 16, placed), 1/2 each",
            &half,
            vec![placed(half_file.clone())],
            cfg,
            0,
        ),
        (
            "3 aligned media (2 layers), 1/3 each",
            &third,
            vec![layer(third_file.clone()), layer(third_file)],
            cfg,
            0,
        ),
        ("MImDA: the volume alone", shot.tf, vec![], &mimda, 5),
        (
            "MImDA: 2 aligned media, 1/2 each",
            &half,
            vec![layer(half_file)],
            &mimda,
            5,
        ),
    ];
    let mut renderers = Vec::new();
    let mut images = Vec::new();
    let mut loads = Vec::new();
    for (_, tf, layers, cfg, _) in &cases {
        let t = std::time::Instant::now();
        let mut r =
            Renderer::with_layers(shot.db, layers, cfg, &AdapterRequest::from_env(None, 0))?;
        r.set_transfer_function(1, tf)?;
        let f = r.converge(shot.placement, &[*shot.view], cfg, measure::CONVERGE_FRAMES)?;
        loads.push((t.elapsed().as_secs_f64() * 1e3, f.stats.bytes_read));
        images.push(f.images.into_iter().next().expect("one view"));
        renderers.push(r);
    }
    let rounds = rounds.max(3);
    let mut ms = vec![Vec::new(); cases.len()];
    for round in 0..rounds {
        for i in measure::round_order(round, cases.len()) {
            let (_, tf, _, cfg, _) = cases[i];
            let (f, _) = timed_frame(
                &mut renderers[i],
                200 + round as u64,
                Shot { tf, ..shot },
                cfg,
            )?;
            ms[i].push(f.stats.render_ms);
        }
    }
    let medians: Vec<f64> = ms.iter_mut().map(|m| measure::median(m)).collect();
    let mut points: Vec<LayerPoint> = Vec::new();
    for (i, (name, _, _, _, b)) in cases.iter().enumerate() {
        let base: Vec<[f64; 4]> = images[*b].iter().map(|p| p.map(f64::from)).collect();
        let e = parallax_backend::metric::image_error(&images[i], &base);
        points.push(LayerPoint {
            name,
            against: cases[*b].0,
            drawn: renderers[i].layer_count(),
            render_ms: medians[i],
            time_ratio: medians[i] / medians[*b],
            rmse: e.rmse,
            equal: images[i]
                .iter()
                .zip(&images[*b])
                .all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)),
            converge_ms: loads[i].0,
            bytes_read: loads[i].1,
        });
    }
    Ok(points)
}

/// The table on stdout.
pub fn print(points: &[LayerPoint]) {
    println!(
        "{:<62} {:>6} {:>10} {:>8} {:>10} {:>6} {:>12} {:>9}",
        "case", "layers", "render ms", "ratio", "RMSE", "equal", "converge ms", "MB read"
    );
    for p in points {
        let LayerPoint {
            name,
            drawn,
            render_ms: ms,
            time_ratio: ratio,
            rmse,
            equal,
            converge_ms: cold,
            ..
        } = p;
        let mb = p.bytes_read as f64 / 1e6;
        println!(
            "{name:<62} {drawn:>6} {ms:>10.1} {ratio:>8.2} {rmse:>10.2e} {equal:>6} {cold:>12.0} {mb:>9.1}"
        );
    }
}

/// DIR/layers.csv.
pub fn write_csv(path: &Path, points: &[LayerPoint]) -> Result<()> {
    write_table(
        path,
        "case,against,layers_drawn,render_ms,time_ratio,rmse_vs_volume,equal,converge_ms,bytes_read",
        points.iter().map(|p| {
            format!(
                "{},{},{},{:.3},{:.3},{:.3e},{},{:.1},{}",
                p.name,
                p.against,
                p.drawn,
                p.render_ms,
                p.time_ratio,
                p.rmse,
                p.equal,
                p.converge_ms,
                p.bytes_read
            )
        }),
    )
}
