//! `parallax bench`: error against the exact integral beside frame time for
//! a sweep of every quality knob (step size, level of detail, 8-bit bricks,
//! early termination), written as CSV and as an SVG work–precision plot.

use crate::reference::{self, Tolerance};
use crate::render::Renderer;
use crate::store::codec::{self, Codec};
use crate::store::BrickEncoding;
use crate::store::{self, ImportOptions};
use crate::volume::{MemorySource, Volume};
use anyhow::{Context, Result};
use parallax_common::atomic::AtomicFile;
use parallax_common::camera::{Placement, View};
use parallax_common::config::{RenderConfig, Shading};
use parallax_common::tf::TransferFunction;
use std::io::Write;
use std::path::Path;
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

/// Error of an image against the reference: RMSE and max abs of the
/// premultiplied RGBA channels, PSNR (peak 1).
pub fn image_error(img: &[[f32; 4]], reference: &[[f64; 4]]) -> (f64, f64, f64) {
    let mut sq = 0.0;
    let mut mx = 0f64;
    for (a, b) in img.iter().zip(reference) {
        for c in 0..4 {
            let d = a[c] as f64 - b[c];
            sq += d * d;
            mx = mx.max(d.abs());
        }
    }
    let rmse = (sq / (4 * img.len().max(1)) as f64).sqrt();
    (rmse, mx, -20.0 * rmse.max(1e-12).log10())
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

/// Runs the sweep and writes `bench.csv` and `bench.svg` into `out`.
pub fn run(o: &BenchOptions) -> Result<Vec<Point>> {
    std::fs::create_dir_all(o.out)?;
    let t = Instant::now();
    let reference = reference::render(
        o.volume,
        o.tf,
        &o.placement,
        &o.view,
        Tolerance { abs: 1e-6 },
    );
    let ref_s = t.elapsed().as_secs_f64();
    eprintln!("reference integral: {ref_s:.1} s");
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
    let base = precise_config();
    let mut sweeps: Vec<(&'static str, f64, &'static str, RenderConfig)> = Vec::new();
    for s in [0.0625, 0.125, 0.25, 0.5, 1.0, 2.0] {
        sweeps.push((
            "step_factor",
            s,
            "full",
            RenderConfig {
                step_factor: s,
                ..base.clone()
            },
        ));
    }
    for a in [1.0, 2.0, 4.0, 8.0, 16.0] {
        sweeps.push((
            "accuracy",
            a,
            "full",
            RenderConfig {
                accuracy: a,
                ..base.clone()
            },
        ));
    }
    sweeps.push((
        "interpolation_exact",
        1.0,
        "full",
        RenderConfig {
            interpolation: parallax_common::config::Interpolation::Exact,
            ..base.clone()
        },
    ));
    // L12's adaptive step (Eq. 3): step_factor 0.5 is λ = t·sin(θ/2).
    for s in [0.25, 0.5, 1.0] {
        sweeps.push((
            "adaptive_step",
            s,
            "full",
            RenderConfig {
                step_factor: s,
                adaptive_step: true,
                ..base.clone()
            },
        ));
    }
    // Multilevel sampling (G10 §4): the accuracy sweep with levels blended.
    for a in [0.5, 1.0, 2.0, 4.0] {
        sweeps.push((
            "multilevel",
            a,
            "full",
            RenderConfig {
                accuracy: a,
                multilevel: true,
                ..base.clone()
            },
        ));
    }
    // Tricubic B-spline filtering (L12 §5.1): the step sweep.
    for s in [0.125, 0.25, 0.5, 1.0] {
        sweeps.push((
            "tricubic",
            s,
            "full",
            RenderConfig {
                step_factor: s,
                filter: parallax_common::config::Filter::Tricubic,
                ..base.clone()
            },
        ));
    }
    // The 2D pre-integration table (one bilinear fetch a segment): the step
    // sweep.
    for s in [0.125, 0.25, 0.5, 1.0] {
        sweeps.push((
            "preintegration_2d",
            s,
            "full",
            RenderConfig {
                step_factor: s,
                preintegration: parallax_common::config::Preintegration::TwoD,
                ..base.clone()
            },
        ));
    }
    // The exact integral in closed form (no table read): the step sweep.
    for s in [0.125, 0.25, 0.5, 1.0] {
        sweeps.push((
            "preintegration_analytic",
            s,
            "full",
            RenderConfig {
                step_factor: s,
                preintegration: parallax_common::config::Preintegration::Analytic,
                ..base.clone()
            },
        ));
    }
    // The old curve: no empty-space skipping inside bricks.
    for s in [0.125, 0.25, 0.5, 1.0] {
        sweeps.push((
            "step_factor_without_macrocells",
            s,
            "full",
            RenderConfig {
                step_factor: s,
                macrocells: false,
                ..base.clone()
            },
        ));
    }
    for e in [0.9, 0.95, 0.99, 0.995, 0.999] {
        sweeps.push((
            "early_termination",
            e,
            "full",
            RenderConfig {
                early_termination: e,
                ..base.clone()
            },
        ));
    }
    for s in [0.125, 0.25, 0.5, 1.0] {
        sweeps.push((
            "step_factor",
            s,
            "8-bit",
            RenderConfig {
                step_factor: s,
                ..base.clone()
            },
        ));
    }
    if o.kernels_only {
        sweeps.clear();
    }
    let mut points = Vec::new();
    for (knob, value, bricks, cfg) in sweeps {
        let db = &paths.iter().find(|(n, _)| *n == bricks).unwrap().1;
        let mut r = Renderer::new(db, &cfg)?;
        r.set_transfer_function(1, o.tf)?;
        let f = r.converge(&o.placement, &[o.view], &cfg, 64)?;
        let mut frame_ms = Vec::new();
        let mut render_ms = Vec::new();
        let mut last = f;
        for i in 0..o.repeats.max(1) {
            let t = Instant::now();
            last = r.frame(100 + i as u64, &o.placement, &[o.view], &cfg)?;
            frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
            render_ms.push(last.stats.render_ms);
        }
        let (rmse, max_abs, psnr) = image_error(&last.images[0], &reference);
        let p = Point {
            knob,
            value,
            bricks,
            frame_ms: median(&mut frame_ms),
            render_ms: median(&mut render_ms),
            rmse,
            max_abs,
            psnr,
            leaves: last.stats.cut_leaves_with_data,
        };
        eprintln!(
            "{knob:>17} = {value:<7} {bricks:>5}: {:8.1} ms/frame, RMSE {:.2e}, max {:.2e}, PSNR {:.1} dB, {} bricks",
            p.frame_ms, p.rmse, p.max_abs, p.psnr, p.leaves
        );
        points.push(p);
    }
    if !o.kernels_only {
        write_csv(&o.out.join("bench.csv"), &points)?;
        plot(&o.out.join("bench.svg"), &points)?;
        let orders = convergence_orders(&points);
        for (knob, bricks, order, of, n) in &orders {
            eprintln!(
                "convergence order of {knob} ({bricks} bricks): {order:.2} in {of} ({n} points)"
            );
        }
        write_table(
            &o.out.join("orders.csv"),
            "knob,bricks,order,of,points",
            orders
                .iter()
                .map(|(knob, bricks, order, of, n)| format!("{knob},{bricks},{order:.3},{of},{n}")),
        )?;
    }
    let kernels = run_kernels(o, &paths[0].1, &base, &reference)?;
    write_kernels_csv(&o.out.join("kernels.csv"), &kernels)?;
    Ok(points)
}

/// One kernel combination's cost (G10 §5: one kernel per combination).
#[derive(Clone, Debug)]
pub struct KernelPoint {
    pub name: &'static str,
    pub frame_ms: f64,
    pub render_ms: f64,
    /// Against the plain DVR image of the same settings (0: identical).
    pub diff_from_dvr: f64,
}

/// Frame time of the enhancer chain and the steppers at the sweep's base
/// settings: no enhancer, the pass-through chain (three), one clip plane,
/// three chained, MImDA, refraction (ν = 1: the kernel alone; ν rising
/// with the data: rays bend). The configurations are timed round-robin, so
/// that a change in the machine's load falls on all of them alike.
pub fn run_kernels(
    o: &BenchOptions,
    db: &Path,
    base: &RenderConfig,
    reference: &[[f64; 4]],
) -> Result<Vec<KernelPoint>> {
    use parallax_common::config::Mode;
    use parallax_common::tf::ControlPoint;
    use parallax_common::tools::{ClipPlane, Tool};
    let cfg = RenderConfig {
        step_factor: 0.5,
        accuracy: 1.0,
        ..base.clone()
    };
    let plane = |x: f64| {
        Tool::ClipPlane(ClipPlane {
            point: [x, 0.0, 0.0],
            normal: [0.3, 0.1, 1.0],
            thickness: 0.004,
            context: [0.3, 0.7],
        })
    };
    let bending = TransferFunction::from_points(
        o.tf.points()
            .iter()
            .map(|p| {
                let (lo, hi) = (o.tf.points()[0].value, o.tf.points().last().unwrap().value);
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
    )?;
    let configs: Vec<(&'static str, Vec<Tool>, RenderConfig, &TransferFunction)> = vec![
        ("dvr, no enhancer", vec![], cfg.clone(), o.tf),
        (
            "pass-through x3",
            vec![Tool::PassThrough; 3],
            cfg.clone(),
            o.tf,
        ),
        ("clip plane x1", vec![plane(0.0)], cfg.clone(), o.tf),
        (
            "clip plane x3",
            vec![plane(-0.02), plane(0.0), plane(0.02)],
            cfg.clone(),
            o.tf,
        ),
        (
            "mimda gamma 0.5",
            vec![],
            RenderConfig {
                mode: Mode::Mimda,
                gamma: 0.5,
                ..cfg.clone()
            },
            o.tf,
        ),
        (
            "refraction, nu = 1",
            vec![],
            RenderConfig {
                refraction: true,
                ..cfg.clone()
            },
            o.tf,
        ),
        (
            "refraction, nu 1..1.1",
            vec![],
            RenderConfig {
                refraction: true,
                ..cfg.clone()
            },
            &bending,
        ),
    ];
    let mut renderers = Vec::new();
    let mut first = Vec::new();
    for (_, tools, c, tf) in &configs {
        let mut r = Renderer::new(db, c)?;
        r.set_transfer_function(1, tf)?;
        r.set_tools(1, tools)?;
        let f = r.converge(&o.placement, &[o.view], c, 64)?;
        first.push(f.images.into_iter().next().unwrap());
        renderers.push(r);
    }
    let rounds = o.repeats.max(5);
    let mut frame_ms = vec![Vec::new(); configs.len()];
    let mut render_ms = vec![Vec::new(); configs.len()];
    for round in 0..rounds {
        // Forwards, then backwards: no configuration always follows the same
        // one.
        let order: Vec<usize> = if round % 2 == 0 {
            (0..configs.len()).collect()
        } else {
            (0..configs.len()).rev().collect()
        };
        for i in order {
            let r = &mut renderers[i];
            let t = Instant::now();
            let f = r.frame(200 + round as u64, &o.placement, &[o.view], &configs[i].2)?;
            frame_ms[i].push(t.elapsed().as_secs_f64() * 1e3);
            render_ms[i].push(f.stats.render_ms);
        }
    }
    let dvr: Vec<[f64; 4]> = first[0].iter().map(|p| p.map(|x| x as f64)).collect();
    let (rmse_dvr, _, _) = image_error(&first[0], reference);
    eprintln!("kernels (RMSE of plain DVR against the exact integral {rmse_dvr:.2e}):");
    let mut out = Vec::new();
    for (i, (name, ..)) in configs.iter().enumerate() {
        let (diff, _, _) = image_error(&first[i], &dvr);
        let p = KernelPoint {
            name,
            frame_ms: median(&mut frame_ms[i]),
            render_ms: median(&mut render_ms[i]),
            diff_from_dvr: diff,
        };
        eprintln!(
            "{:>22}: {:8.1} ms/frame ({:8.1} ms in the kernel), {:.2}× plain DVR, differs from it by RMSE {:.2e}",
            p.name,
            p.frame_ms,
            p.render_ms,
            p.render_ms / out.first().map_or(p.render_ms, |q: &KernelPoint| q.render_ms),
            p.diff_from_dvr
        );
        out.push(p);
    }
    Ok(out)
}

fn write_kernels_csv(path: &Path, points: &[KernelPoint]) -> Result<()> {
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
            if xy.len() < 2 {
                return None;
            }
            let n = xy.len() as f64;
            let (mx, my) = xy
                .iter()
                .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
            let sxx: f64 = xy.iter().map(|(x, _)| (x - mx).powi(2)).sum();
            let sxy: f64 = xy.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
            (sxx > 0.0).then(|| (knob, bricks, sxy / sxx, of, xy.len()))
        })
        .collect()
}

/// The sweep's base: every knob precise (full detail, step 1/4, rays to the
/// end, no visibility culling, no shading: the reference integral's
/// optics), caches large enough for any test volume.
fn precise_config() -> RenderConfig {
    RenderConfig {
        accuracy: 0.01,
        step_factor: 0.25,
        early_termination: 1.0,
        visibility_feedback: false,
        shading: Shading::None,
        cpu_cache_mb: 2048.0,
        gpu_cache_mb: 1024.0,
        upload_budget: 100_000,
        ..RenderConfig::default()
    }
}

/// Writes a CSV file (atomically): the header line, then one line a row.
fn write_table(path: &Path, header: &str, rows: impl IntoIterator<Item = String>) -> Result<()> {
    let mut f = AtomicFile::create(path)?;
    writeln!(f, "{header}")?;
    for r in rows {
        writeln!(f, "{r}")?;
    }
    f.commit()
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
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

/// Work–precision plot: RMSE (log) against frame time, one series per knob.
fn plot(path: &Path, points: &[Point]) -> Result<()> {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (800, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let tmax = points.iter().map(|p| p.frame_ms).fold(1.0, f64::max) * 1.1;
    let emin = points.iter().map(|p| p.rmse.max(1e-7)).fold(1.0, f64::min) / 2.0;
    let emax = points.iter().map(|p| p.rmse).fold(1e-6, f64::max) * 2.0;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "error against the exact integral vs frame time",
            ("sans-serif", 20),
        )
        .margin(16)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..tmax, (emin..emax).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("frame time (ms)")
        .y_desc("RMSE (premultiplied RGBA)")
        .draw()?;
    let series = [
        ("step_factor", "full", RED),
        (
            "step_factor_without_macrocells",
            "full",
            RGBColor(120, 120, 120),
        ),
        ("adaptive_step", "full", RGBColor(230, 140, 0)),
        ("multilevel", "full", RGBColor(0, 160, 160)),
        ("tricubic", "full", RGBColor(140, 70, 20)),
        ("preintegration_2d", "full", RGBColor(120, 0, 200)),
        ("preintegration_analytic", "full", RGBColor(200, 0, 120)),
        ("accuracy", "full", BLUE),
        ("early_termination", "full", GREEN),
        ("step_factor", "8-bit", MAGENTA),
    ];
    for (knob, bricks, color) in series {
        let pts: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.knob == knob && p.bricks == bricks)
            .map(|p| (p.frame_ms, p.rmse.max(1e-7)))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(format!("{knob} ({bricks} bricks)"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// One codec on one volume's bricks (`parallax bench --codecs`).
#[derive(Clone, Debug)]
pub struct CodecPoint {
    pub volume: String,
    pub codec: String,
    /// Bytes of the source volume, of the quantised bricks before
    /// compression, and of the stored bricks.
    pub source_bytes: u64,
    pub raw_bytes: u64,
    pub stored_bytes: u64,
    /// One thread, MB/s of quantised bytes in (encode) and out (decode).
    pub encode_mb_s: f64,
    pub decode_mb_s: f64,
    /// Decode speed in MB/s of stored bytes read: what the disk must beat
    /// for decoding to be the bottleneck.
    pub decode_in_mb_s: f64,
}

/// The codecs `--codecs` compares.
pub fn codec_candidates() -> Vec<Codec> {
    [
        "lz4",
        "lz4+delta",
        "lz4+auto",
        "zstd1",
        "zstd2",
        "zstd3",
        "zstd1+delta",
        "zstd2+delta",
        "zstd3+delta",
        "zstd1+auto",
        "zstd2+auto",
        "zstd3+auto",
    ]
    .iter()
    .map(|s| Codec::parse(s).expect("a known codec"))
    .collect()
}

/// Imports each volume (bricks of 32, `encoding`), then compresses and
/// decompresses its quantised bricks with every candidate codec on one
/// thread, timing each; writes `codecs.csv` in `out`.
pub fn run_codecs(
    volumes: &[std::path::PathBuf],
    encoding: BrickEncoding,
    out: &Path,
) -> Result<Vec<CodecPoint>> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let tmp = tempfile::tempdir()?;
    let mut points = Vec::new();
    for path in volumes {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut src = crate::data::open(path, None)?;
        let source_bytes = src.info().source_bytes();
        let db_path = tmp.path().join("codec-bench.pxo");
        let opts = ImportOptions {
            encoding,
            codec: Codec::LZ4,
            ..Default::default()
        };
        store::import(src.as_mut(), &db_path, &name, &opts)?;
        let db = store::OctreeDb::open(&db_path)?;
        let len = db.layout().stored_len() * bytes_per(encoding);
        let mut raws = Vec::new();
        for n in db.nodes.iter().filter(|n| n.is_stored()) {
            let stored = db.read_stored(n.key)?.expect("stored");
            raws.push(
                codec::decompress(&stored, encoding, len, db.framing())
                    .map_err(|e| anyhow::anyhow!("{name}: brick {}: {e}", n.key))?,
            );
        }
        let raw_bytes: u64 = raws.iter().map(|r| r.len() as u64).sum();
        for c in codec_candidates() {
            let t = Instant::now();
            let stored: Vec<Vec<u8>> = raws
                .iter()
                .map(|r| codec::compress(r, encoding, c))
                .collect();
            let enc_s = t.elapsed().as_secs_f64();
            let stored_bytes: u64 = stored.iter().map(|s| s.len() as u64).sum();
            // Decode several times for a stable figure on a busy machine.
            let reps = 3;
            let t = Instant::now();
            for _ in 0..reps {
                for (s, r) in stored.iter().zip(&raws) {
                    let d = codec::decompress(s, encoding, len, codec::Framing::Tagged)
                        .map_err(|e| anyhow::anyhow!("{name}: {}: {e}", c.name()))?;
                    anyhow::ensure!(&d == r, "{name}: {} is not lossless", c.name());
                }
            }
            let dec_s = t.elapsed().as_secs_f64() / reps as f64;
            points.push(CodecPoint {
                volume: name.clone(),
                codec: c.name(),
                source_bytes,
                raw_bytes,
                stored_bytes,
                encode_mb_s: raw_bytes as f64 / 1e6 / enc_s,
                decode_mb_s: raw_bytes as f64 / 1e6 / dec_s,
                decode_in_mb_s: stored_bytes as f64 / 1e6 / dec_s,
            });
        }
    }
    write_table(
        &out.join("codecs.csv"),
        "volume,codec,source_bytes,raw_brick_bytes,stored_bytes,ratio_to_source,ratio_to_raw,encode_mb_s,decode_mb_s,decode_in_mb_s",
        points.iter().map(|p| {
            format!(
                "{},{},{},{},{},{:.3},{:.3},{:.1},{:.1},{:.1}",
                p.volume,
                p.codec,
                p.source_bytes,
                p.raw_bytes,
                p.stored_bytes,
                p.source_bytes as f64 / p.stored_bytes as f64,
                p.raw_bytes as f64 / p.stored_bytes as f64,
                p.encode_mb_s,
                p.decode_mb_s,
                p.decode_in_mb_s
            )
        }),
    )?;
    Ok(points)
}

fn bytes_per(encoding: BrickEncoding) -> usize {
    match encoding {
        BrickEncoding::U8Range => 1,
        BrickEncoding::U16Range => 2,
        BrickEncoding::F32 => 4,
    }
}

/// One frame of the reconstruction benchmark.
#[derive(Clone, Debug)]
pub struct ReconstructionPoint {
    pub frame: usize,
    pub full_ms: f64,
    pub reconstructed_ms: f64,
    pub psnr_db: f64,
}

/// Adaptive frame reconstruction (G10 §5) against full rendering over a
/// sequence of placements (an interaction script): both renderers converge
/// their cut on the first, then render one frame per placement (loads
/// waited for, so both see the same cut); the frame time of each and the
/// PSNR of the reconstructed frame against the full one. Writes `reconstruction.csv` in `out`.
pub fn run_reconstruction(
    db: &Path,
    tf: &TransferFunction,
    placements: &[Placement],
    view: View,
    out: &Path,
) -> Result<Vec<ReconstructionPoint>> {
    anyhow::ensure!(!placements.is_empty(), "reconstruction bench: no frames");
    let placement = placements[0];
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let full_cfg = RenderConfig {
        shading: Shading::Phong,
        ..RenderConfig::default()
    };
    let rec_cfg = RenderConfig {
        reconstruction: true,
        ..full_cfg.clone()
    };
    let mut full = Renderer::new(db, &full_cfg)?;
    let mut rec = Renderer::new(db, &rec_cfg)?;
    full.set_transfer_function(1, tf)?;
    rec.set_transfer_function(1, tf)?;
    full.converge(&placement, &[view], &full_cfg, 40)?;
    rec.converge(&placement, &[view], &full_cfg, 40)?;
    full.sync_io = true;
    rec.sync_io = true;
    let mut points = Vec::new();
    for (f, p) in placements.iter().enumerate() {
        let t = Instant::now();
        let a = full.frame(f as u64, p, &[view], &full_cfg)?;
        let full_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let b = rec.frame(f as u64, p, &[view], &rec_cfg)?;
        let reconstructed_ms = t.elapsed().as_secs_f64() * 1e3;
        let reference: Vec<[f64; 4]> = a.images[0].iter().map(|p| p.map(|v| v as f64)).collect();
        points.push(ReconstructionPoint {
            frame: f,
            full_ms,
            reconstructed_ms,
            psnr_db: image_error(&b.images[0], &reference).2,
        });
    }
    write_table(
        &out.join("reconstruction.csv"),
        "frame,full_ms,reconstructed_ms,psnr_db",
        points.iter().map(|p| {
            format!(
                "{},{:.3},{:.3},{:.2}",
                p.frame, p.full_ms, p.reconstructed_ms, p.psnr_db
            )
        }),
    )?;
    Ok(points)
}

/// One frame of the prediction-buffer benchmark.
#[derive(Clone, Debug)]
pub struct PredictionPoint {
    pub kappa: [f64; 2],
    pub frame: usize,
    pub full_ms: f64,
    pub predicted_ms: f64,
    /// The prediction buffer steered this frame (else a full traversal).
    pub predicted: bool,
    /// Pixels whose colour or opacity differs by more than 1/255 from the
    /// full traversal's.
    pub differing: f64,
    /// The image equals the full traversal's bit for bit.
    pub identical: bool,
    /// PSNR against the full traversal (dB).
    pub psnr_db: f64,
}

/// The prediction buffer (B10 §4) against full traversal on an isosurface
/// over a sequence of placements (an interaction script), for each κ pair;
/// both renderers first converge their cut. Writes `prediction.csv` in `out`.
#[allow(clippy::too_many_arguments)]
pub fn run_prediction(
    db: &Path,
    tf: &TransferFunction,
    isovalue: f64,
    placements: &[Placement],
    view: View,
    kappas: &[[f64; 2]],
    out: &Path,
) -> Result<Vec<PredictionPoint>> {
    anyhow::ensure!(!placements.is_empty(), "prediction bench: no frames");
    let placement = placements[0];
    use parallax_common::config::Mode;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    // Visibility feedback off in both, so that both render the same cut
    // and differences come from the traversal alone.
    let full_cfg = RenderConfig {
        mode: Mode::Iso,
        isovalue: Some(isovalue),
        shading: Shading::Phong,
        visibility_feedback: false,
        ..RenderConfig::default()
    };
    let mut full = Renderer::new(db, &full_cfg)?;
    full.set_transfer_function(1, tf)?;
    full.converge(&placement, &[view], &full_cfg, 40)?;
    full.sync_io = true;
    let mut points = Vec::new();
    for &kappa in kappas {
        let cfg = RenderConfig {
            prediction: true,
            kappa,
            ..full_cfg.clone()
        };
        let mut pb = Renderer::new(db, &cfg)?;
        pb.set_transfer_function(1, tf)?;
        pb.converge(&placement, &[view], &full_cfg, 40)?;
        pb.sync_io = true;
        for (f, p) in placements.iter().enumerate() {
            let t = Instant::now();
            let a = full.frame(f as u64, p, &[view], &full_cfg)?;
            let full_ms = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            let b = pb.frame(f as u64, p, &[view], &cfg)?;
            let predicted_ms = t.elapsed().as_secs_f64() * 1e3;
            let (x, y) = (&a.images[0], &b.images[0]);
            let differ = x
                .iter()
                .zip(y)
                .filter(|(p, q)| (0..4).any(|c| (p[c] - q[c]).abs() > 1.0 / 255.0))
                .count();
            points.push(PredictionPoint {
                kappa,
                frame: f,
                full_ms,
                predicted_ms,
                predicted: b.predicted,
                differing: differ as f64 / x.len().max(1) as f64,
                identical: x == y,
                psnr_db: {
                    let r: Vec<[f64; 4]> = x.iter().map(|p| p.map(|v| v as f64)).collect();
                    image_error(y, &r).2
                },
            });
        }
    }
    write_table(
        &out.join("prediction.csv"),
        "kappa_low,kappa_high,frame,full_ms,predicted_ms,predicted,differing_fraction,identical,psnr_db",
        points.iter().map(|p| {
            format!(
                "{},{},{},{:.3},{:.3},{},{:.6},{},{:.2}",
                p.kappa[0],
                p.kappa[1],
                p.frame,
                p.full_ms,
                p.predicted_ms,
                p.predicted,
                p.differing,
                p.identical,
                p.psnr_db
            )
        }),
    )?;
    Ok(points)
}

/// One volume and view of `parallax bench --anisotropy`.
#[derive(Clone, Debug)]
pub struct AnisotropyPoint {
    pub volume: &'static str,
    pub spacing: [f64; 3],
    pub dims: [usize; 3],
    /// "near" or "far" (the volume four times smaller on screen).
    pub view: &'static str,
    pub accuracy: f64,
    /// Multilevel sampling (G10 §4) on.
    pub multilevel: bool,
    pub rmse: f64,
    pub max_abs: f64,
    pub bricks: u64,
    pub frame_ms: f64,
}

/// The level-of-detail error on thick slices: the same CT-like phantom
/// (Shepp–Logan geometry, integer values 0…1000) over the same 256 mm
/// cube, once with isotropic 1 mm voxels (256³) and once as a clinical scan
/// with 0.5 × 0.5 mm pixels and 4 mm slices (512 × 512 × 64; imported
/// twice: levels that halve the finer axes first, and, for comparison,
/// levels that halve all three), seen obliquely at 256×192, near (a source
/// millimetre is about 0.6 pixels) and far (0.15 pixels). Each is rendered
/// at the default accuracy, the thick slices also at full detail (accuracy
/// 0.01) and with multilevel sampling (blending each leaf with its parent
/// and grandparent across the split axes), with every other knob precise (full-precision bricks, exact
/// interpolation, step 1/4, no early termination), and compared with its
/// own exact integral: the difference between the two accuracies is what
/// the level of detail costs. Writes `anisotropy.csv`.
pub fn run_anisotropy(out: &Path) -> Result<Vec<AnisotropyPoint>> {
    anisotropy_study(out, 256, [256, 192], 0.25)
}

/// [`run_anisotropy`] on a cube of `mm` millimetres (isotropic mm³ voxels
/// and 2mm × 2mm × mm/4 of 0.5 × 0.5 × 4 mm), `size` metres tall on screen
/// near and a quarter of that far, seen at `resolution` on the 0.4 × 0.3 m
/// window.
pub fn anisotropy_study(
    out: &Path,
    mm: usize,
    resolution: [u32; 2],
    size: f64,
) -> Result<Vec<AnisotropyPoint>> {
    use crate::data::synth::{coord, shepp_logan};
    use crate::volume::VoxelType;
    use parallax_common::tf::ControlPoint;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(40.0, [0.0; 3], 0.0),
        ControlPoint::new(150.0, [0.9, 0.55, 0.35], 0.01),
        ControlPoint::new(400.0, [0.9, 0.85, 0.7], 0.04),
        ControlPoint::new(1000.0, [1.0; 3], 0.2),
    ])?;
    let placement = |size: f64| Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [-70.0, 25.0, 0.0],
        size,
    };
    let view = View::window(resolution, [0.4, 0.3], [0.0, 0.0, 0.8]);
    let views = [("near", size), ("far", size / 4.0)];
    let tmp = tempfile::tempdir()?;
    let mut points = Vec::new();
    let default = RenderConfig::default().accuracy;
    // The thick slices in the octree whose levels halve every axis (before
    // format 5, `--isotropic-levels`) and in the one whose levels halve the
    // finer axes first.
    // (name, isotropic levels, (accuracy, multilevel) renders) of each
    // import of a volume.
    type Imports<'a> = &'a [(&'static str, bool, &'a [(f64, bool)])];
    let volumes: [(&str, [usize; 3], [f64; 3], Imports<'_>); 2] = [
        (
            "isotropic 1 mm",
            [mm, mm, mm],
            [1.0, 1.0, 1.0],
            &[(
                "isotropic 1 mm",
                false,
                &[(default, false), (default, true)],
            )],
        ),
        (
            "0.5 x 0.5 x 4 mm slices",
            [2 * mm, 2 * mm, mm / 4],
            [0.5, 0.5, 4.0],
            &[
                (
                    "0.5 x 0.5 x 4 mm slices",
                    false,
                    &[(default, false), (0.01, false), (default, true)],
                ),
                (
                    "0.5 x 0.5 x 4 mm slices (levels halving all axes)",
                    true,
                    &[(default, false)],
                ),
            ],
        ),
    ];
    for (vname, dims, spacing, imports) in volumes {
        let vol = Volume::from_fn(dims, spacing, VoxelType::U16, |i, j, k| {
            (1000.0 * shepp_logan([coord(i, dims[0]), coord(j, dims[1]), coord(k, dims[2])]))
                .round() as f32
        });
        let references: Vec<Vec<[f64; 4]>> = views
            .iter()
            .map(|&(vw, sz)| {
                let t = Instant::now();
                let r =
                    reference::render(&vol, &tf, &placement(sz), &view, Tolerance { abs: 1e-6 });
                eprintln!(
                    "{vname}, {vw}: reference integral {:.1} s",
                    t.elapsed().as_secs_f64()
                );
                r
            })
            .collect();
        for &(name, isotropic_levels, accuracies) in imports {
            let db = tmp.path().join("aniso.pxo");
            store::import(
                &mut MemorySource::new(&vol),
                &db,
                name,
                &ImportOptions {
                    encoding: BrickEncoding::F32,
                    isotropic_levels,
                    ..Default::default()
                },
            )?;
            for (&(vw, sz), reference) in views.iter().zip(&references) {
                for &(accuracy, multilevel) in accuracies {
                    let cfg = RenderConfig {
                        accuracy,
                        multilevel,
                        interpolation: parallax_common::config::Interpolation::Exact,
                        ..precise_config()
                    };
                    let (f, frame_ms) = converged_frame(&db, &tf, &placement(sz), &view, &cfg)?;
                    let (rmse, max_abs, _) = image_error(&f.images[0], reference);
                    let p = AnisotropyPoint {
                        volume: name,
                        spacing,
                        dims,
                        view: vw,
                        accuracy,
                        multilevel,
                        rmse,
                        max_abs,
                        bricks: f.stats.cut_leaves_with_data,
                        frame_ms,
                    };
                    eprintln!(
                        "{name:>50}, {vw:>4}, accuracy {accuracy:<5}{}: RMSE {rmse:.2e}, max {max_abs:.2e}, {} bricks, {frame_ms:.0} ms",
                        if multilevel { ", multilevel" } else { "" },
                        p.bricks
                    );
                    points.push(p);
                }
            }
        }
    }
    write_table(
        &out.join("anisotropy.csv"),
        "volume,spacing_mm,dims,view,accuracy,multilevel,rmse,max_abs,bricks_in_cut,frame_ms",
        points.iter().map(|p| {
            let [sx, sy, sz] = p.spacing;
            let [nx, ny, nz] = p.dims;
            format!(
                "{},{sx}x{sy}x{sz},{nx}x{ny}x{nz},{},{},{},{:.6e},{:.6e},{},{:.1}",
                p.volume, p.view, p.accuracy, p.multilevel, p.rmse, p.max_abs, p.bricks, p.frame_ms
            )
        }),
    )?;
    for (vw, _) in views {
        let at_default = |v: &str| {
            points
                .iter()
                .find(|p| p.volume == v && p.view == vw && p.accuracy == default && !p.multilevel)
                .map(|p| (p.rmse, p.bricks))
                .unwrap_or((f64::NAN, 0))
        };
        let iso = at_default("isotropic 1 mm");
        let fitted = at_default("0.5 x 0.5 x 4 mm slices");
        let all = at_default("0.5 x 0.5 x 4 mm slices (levels halving all axes)");
        eprintln!(
            "{vw}: thick slices / isotropic error at the default accuracy: {:.2} ({} bricks; \
             levels halving all axes: {:.2}, {} bricks)",
            fitted.0 / iso.0,
            fitted.1,
            all.0 / iso.0,
            all.1
        );
    }
    Ok(points)
}

/// A frame of `view` once the cut has converged, and its wall time (ms).
fn converged_frame(
    db: &Path,
    tf: &TransferFunction,
    placement: &Placement,
    view: &View,
    cfg: &RenderConfig,
) -> Result<(crate::render::Frame, f64)> {
    let mut r = Renderer::new(db, cfg)?;
    r.set_transfer_function(1, tf)?;
    r.converge(placement, &[*view], cfg, 64)?;
    let t = Instant::now();
    let f = r.frame(100, placement, &[*view], cfg)?;
    Ok((f, t.elapsed().as_secs_f64() * 1e3))
}

/// One accuracy of [`seam_study`]: one level of detail per brick against
/// multilevel sampling.
#[derive(Clone, Debug)]
pub struct SeamPoint {
    pub accuracy: f64,
    /// Neighbouring pixel pairs that straddle a level change: one ray met
    /// only full-detail bricks (its pixel is within 1e-4 of the full-detail
    /// image's), the other a coarser one.
    pub seam_pairs: usize,
    /// The largest amount by which a step across those pairs exceeds the
    /// same step in the full-detail image, one level per brick (the seam)
    /// and with multilevel sampling (blurring adds nothing).
    pub jump_before: f64,
    pub jump_after: f64,
    /// RMSE against the exact integral, before and after.
    pub rmse_before: f64,
    pub rmse_after: f64,
    /// Leaves with data in the cut, before and after (multilevel sampling
    /// also refines a node by the point-wise size it blends by).
    pub bricks: u64,
    pub bricks_after: u64,
    pub ms_before: f64,
    pub ms_after: f64,
}

/// `parallax bench --seams`: a thin slab of a smooth field seen face-on
/// from close by, so that the cut holds finer bricks at the centre than at
/// the edges, rendered with one level of detail per brick and with
/// multilevel sampling (G10 §4, Fig. 5). Writes `seams.csv` and the images.
pub fn run_seams(out: &Path) -> Result<Vec<SeamPoint>> {
    seam_study(out, 128, [384, 288])
}

/// [`run_seams`] on an n × n × n/8 slab at `resolution` (n / width fixed
/// at 2/3 keeps the levels where they are: a leaf voxel about a pixel at
/// the centre, two at the corners).
pub fn seam_study(out: &Path, n: usize, resolution: [u32; 2]) -> Result<Vec<SeamPoint>> {
    use crate::volume::VoxelType;
    use parallax_common::tf::ControlPoint;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    // Waves 8 voxels long: the first coarser level keeps a third of them.
    let wave = |i: usize| (std::f64::consts::TAU * (i as f64 + 0.5) / 8.0).sin();
    let vol = Volume::from_fn([n, n, n / 8], [1.0; 3], VoxelType::F32, |i, j, _| {
        (0.5 + 0.4 * wave(i) * wave(j)) as f32
    });
    // Opaque: each pixel shows the value where its ray meets the slab, so
    // a level change between bricks shows as a step (G10 Fig. 5).
    let tf = TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.1, 0.3, 0.9], 20.0),
        ControlPoint::new(1.0, [1.0, 0.8, 0.3], 20.0),
    ])?;
    let placement = Placement {
        center: [0.0, 0.0, 0.0],
        rotation_deg: [-45.0, 0.0, 0.0],
        size: 0.3,
    };
    let view = View::window(resolution, [0.4, 0.3], [0.0, 0.0, 0.25]);
    let reference = reference::render(&vol, &tf, &placement, &view, Tolerance { abs: 1e-6 });
    let tmp = tempfile::tempdir()?;
    let db = tmp.path().join("seams.pxo");
    store::import(
        &mut MemorySource::new(&vol),
        &db,
        "slab of waves",
        &ImportOptions {
            brick: 16,
            encoding: BrickEncoding::F32,
            ..Default::default()
        },
    )?;
    let render = |accuracy: f64, multilevel: bool| -> Result<(Vec<[f32; 4]>, u64, f64)> {
        let cfg = RenderConfig {
            accuracy,
            multilevel,
            interpolation: parallax_common::config::Interpolation::Exact,
            ..precise_config()
        };
        let (f, ms) = converged_frame(&db, &tf, &placement, &view, &cfg)?;
        Ok((f.images[0].clone(), f.stats.cut_leaves_with_data, ms))
    };
    let (full, _, _) = render(0.01, false)?;
    let w = resolution[0] as usize;
    let diff = |img: &[[f32; 4]]| -> Vec<[f64; 4]> {
        img.iter()
            .zip(&full)
            .map(|(a, b)| std::array::from_fn(|c| a[c] as f64 - b[c] as f64))
            .collect()
    };
    // Pixels whose 5 × 5 neighbourhood lies inside the volume's image: at
    // the silhouette the rays leave through the sides, which is no seam.
    let h = resolution[1] as usize;
    let interior: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            (y - 2..=y + 2).all(|v| {
                (x - 2..=x + 2).all(|u| {
                    (0..w as i64).contains(&u)
                        && (0..h as i64).contains(&v)
                        && full[v as usize * w + u as usize][3] > 1e-3
                })
            })
        })
        .collect();
    let mut points = Vec::new();
    for accuracy in [4.0, 8.0] {
        let (before, bricks, ms_before) = render(accuracy, false)?;
        let (after, bricks_after, ms_after) = render(accuracy, true)?;
        let e0 = diff(&before);
        // A ray that met full-detail bricks only (or that a coarse brick
        // changed by less than 1e-4) against one that a coarse one changed.
        let exact = |i: usize| e0[i].iter().all(|&v| v.abs() < 1e-4);
        // How much larger a step between two pixels is than the same step in
        // the full-detail image: a seam adds to it, blurring does not.
        let step = |img: &[[f32; 4]], i: usize, j: usize| {
            (0..4)
                .map(|c| {
                    let d = (img[j][c] - img[i][c]).abs() - (full[j][c] - full[i][c]).abs();
                    d as f64
                })
                .fold(0.0, f64::max)
        };
        let (mut pairs, mut jump_before, mut jump_after) = (0, 0f64, 0f64);
        for i in 0..e0.len() {
            for j in [i + 1, i + w] {
                if (j == i + 1 && j % w == 0)
                    || j >= e0.len()
                    || !interior[i]
                    || !interior[j]
                    || exact(i) == exact(j)
                {
                    continue;
                }
                pairs += 1;
                jump_before = jump_before.max(step(&before, i, j));
                jump_after = jump_after.max(step(&after, i, j));
            }
        }
        for (name, img) in [("one-level", &before), ("multilevel", &after)] {
            crate::output::write_png(
                &out.join(format!("seams-accuracy{accuracy}-{name}.png")),
                resolution[0],
                resolution[1],
                img,
            )?;
        }
        let p = SeamPoint {
            accuracy,
            seam_pairs: pairs,
            jump_before,
            jump_after,
            rmse_before: image_error(&before, &reference).0,
            rmse_after: image_error(&after, &reference).0,
            bricks,
            bricks_after,
            ms_before,
            ms_after,
        };
        eprintln!(
            "accuracy {accuracy}: {} → {} bricks, {pairs} pixel pairs across level changes; largest \
             step there {:.2e} with one level per brick, {:.2e} with multilevel sampling; RMSE \
             {:.2e} → {:.2e}; {:.0} → {:.0} ms",
            p.bricks,
            p.bricks_after,
            p.jump_before,
            p.jump_after,
            p.rmse_before,
            p.rmse_after,
            p.ms_before,
            p.ms_after
        );
        points.push(p);
    }
    write_table(
        &out.join("seams.csv"),
        "accuracy,bricks_one_level,bricks_multilevel,seam_pixel_pairs,jump_one_level,jump_multilevel,rmse_one_level,rmse_multilevel,ms_one_level,ms_multilevel",
        points.iter().map(|p| {
            format!(
                "{},{},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.1},{:.1}",
                p.accuracy,
                p.bricks,
                p.bricks_after,
                p.seam_pairs,
                p.jump_before,
                p.jump_after,
                p.rmse_before,
                p.rmse_after,
                p.ms_before,
                p.ms_after
            )
        }),
    )?;
    Ok(points)
}
