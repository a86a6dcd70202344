//! Studies along an interaction script: adaptive frame reconstruction
//! (G10 §5) and the isosurface prediction buffer (B10 §4), each against
//! full rendering of the same placements (`parallax bench reconstruction`,
//! `parallax bench prediction`).

use crate::measure::{self, timed_frame, write_table, Shot};
use anyhow::Result;
use parallax_backend::data;
use parallax_backend::metric::{as_reference, image_error, pixels_off};
use parallax_backend::render::Renderer;
use parallax_backend::store::{self, ImportOptions};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Mode, RenderConfig, Shading};
use parallax_common::tf::TransferFunction;
use std::path::{Path, PathBuf};

/// Frames the renderers of a sequence converge their cut over.
const SEQUENCE_CONVERGE_FRAMES: usize = 40;

/// What a sequence study renders: a volume imported to a temporary
/// database, the placements of an interaction script's first frames, the
/// desktop view.
pub struct Sequence {
    pub tf: TransferFunction,
    pub db: PathBuf,
    pub placements: Vec<Placement>,
    pub view: View,
    /// Holds the database.
    _dir: tempfile::TempDir,
}

/// The placement the studies start from: Colin27 upright, facing the
/// viewer, 25 cm tall.
pub const START: Placement = Placement {
    center: [0.0, 0.0, 0.0],
    rotation_deg: [-90.0, 180.0, 0.0],
    size: 0.25,
};

/// The desktop window of the studies: 0.4 × 0.3 m, the eye 0.8 m in front.
pub fn desktop_view(size: [u32; 2]) -> View {
    View::window(size, [0.4, 0.3], [0.0, 0.0, 0.8])
}

impl Sequence {
    /// `volume` imported with the default options, `tf`, and the first
    /// `frames` placements of `script` from [`START`], seen at `size`.
    pub fn new(
        volume: &Path,
        tf: &Path,
        script: &Path,
        frames: usize,
        size: [u32; 2],
    ) -> Result<Sequence> {
        let tf = TransferFunction::load(tf)?;
        let dir = tempfile::tempdir()?;
        let db = dir.path().join("bench.pxo");
        let mut src = data::open(volume, None)?;
        store::import(
            src.as_mut(),
            &db,
            &volume.display().to_string(),
            &ImportOptions::default(),
        )?;
        let s = parallax_frontend::script::Script::load(script)?;
        anyhow::ensure!(
            frames as u64 <= s.frames,
            "{}: has {} frames, {frames} asked for",
            script.display(),
            s.frames
        );
        let placements = (0..frames as u64)
            .map(|f| s.at(f, &START, [0.0, 0.0, 0.8], 0.0).placement)
            .collect();
        Ok(Sequence {
            tf,
            db,
            placements,
            view: desktop_view(size),
            _dir: dir,
        })
    }

    fn shot<'a>(&'a self, placement: &'a Placement) -> Shot<'a> {
        Shot {
            db: &self.db,
            tf: &self.tf,
            placement,
            view: &self.view,
        }
    }

    /// A renderer with `cfg` whose cut converged with `converge_cfg` on the
    /// first placement, then waiting for every load (so that two renderers
    /// see the same cut).
    fn renderer(&self, cfg: &RenderConfig, converge_cfg: &RenderConfig) -> Result<Renderer> {
        anyhow::ensure!(!self.placements.is_empty(), "sequence study: no frames");
        let mut r = Renderer::new(&self.db, cfg)?;
        r.set_transfer_function(1, &self.tf)?;
        r.converge(
            &self.placements[0],
            &[self.view],
            converge_cfg,
            SEQUENCE_CONVERGE_FRAMES,
        )?;
        r.sync_io = true;
        Ok(r)
    }
}

/// One frame of the reconstruction study.
#[derive(Clone, Debug)]
pub struct ReconstructionPoint {
    pub frame: usize,
    pub full_ms: f64,
    pub reconstructed_ms: f64,
    pub psnr_db: f64,
}

/// Adaptive frame reconstruction (G10 §5) against full rendering over the
/// sequence: both renderers converge their cut on the first placement,
/// then render one frame per placement (loads waited for, so both see the
/// same cut); the frame time of each and the PSNR of the reconstructed
/// frame against the full one. Writes `reconstruction.csv` in `out`.
pub fn reconstruction(s: &Sequence, out: &Path) -> Result<Vec<ReconstructionPoint>> {
    measure::create_out(out)?;
    let full_cfg = RenderConfig {
        shading: Shading::Phong,
        ..RenderConfig::default()
    };
    let rec_cfg = RenderConfig {
        reconstruction: true,
        ..full_cfg.clone()
    };
    let mut full = s.renderer(&full_cfg, &full_cfg)?;
    let mut rec = s.renderer(&rec_cfg, &full_cfg)?;
    let mut points = Vec::new();
    for (f, p) in s.placements.iter().enumerate() {
        let (a, full_ms) = timed_frame(&mut full, f as u64, s.shot(p), &full_cfg)?;
        let (b, reconstructed_ms) = timed_frame(&mut rec, f as u64, s.shot(p), &rec_cfg)?;
        points.push(ReconstructionPoint {
            frame: f,
            full_ms,
            reconstructed_ms,
            psnr_db: image_error(&b.images[0], &as_reference(&a.images[0])).psnr_db,
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

/// Prints the reconstruction study's speed-up and PSNR.
pub fn print_reconstruction(s: &Sequence, script: &Path, points: &[ReconstructionPoint]) {
    let frames = points.len().max(1) as f64;
    let full: f64 = points.iter().map(|p| p.full_ms).sum();
    let rec: f64 = points.iter().map(|p| p.reconstructed_ms).sum();
    let mean = points.iter().map(|p| p.psnr_db).sum::<f64>() / frames;
    let worst = points
        .iter()
        .map(|p| p.psnr_db)
        .fold(f64::INFINITY, f64::min);
    println!(
        "{} frames of {}, {}×{}: full {:.1} ms/frame, reconstructed {:.1} ms/frame: speed-up {:.2}×; PSNR against full mean {mean:.1} dB, worst {worst:.1} dB",
        points.len(),
        script.display(),
        s.view.resolution[0],
        s.view.resolution[1],
        full / frames,
        rec / frames,
        full / rec
    );
}

/// One frame of the prediction-buffer study.
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

/// The κ pairs the prediction study tries (B10 §4.5).
pub const KAPPAS: [[f64; 2]; 5] = [[0.1, 0.3], [0.2, 0.6], [0.5, 1.0], [1.0, 2.0], [2.0, 2.0]];

/// The prediction buffer (B10 §4) against full traversal on the isosurface
/// at `isovalue` over the sequence, for each κ pair; both renderers first
/// converge their cut, with visibility feedback off in both so that both
/// render the same cut and differences come from the traversal alone.
/// Writes `prediction.csv` in `out`.
pub fn prediction(
    s: &Sequence,
    isovalue: f64,
    kappas: &[[f64; 2]],
    out: &Path,
) -> Result<Vec<PredictionPoint>> {
    measure::create_out(out)?;
    let full_cfg = RenderConfig {
        mode: Mode::Iso,
        isovalue: Some(isovalue),
        shading: Shading::Phong,
        visibility_feedback: false,
        ..RenderConfig::default()
    };
    let mut full = s.renderer(&full_cfg, &full_cfg)?;
    let mut points = Vec::new();
    for &kappa in kappas {
        let cfg = RenderConfig {
            prediction: true,
            kappa,
            ..full_cfg.clone()
        };
        let mut pb = s.renderer(&cfg, &full_cfg)?;
        for (f, p) in s.placements.iter().enumerate() {
            let (a, full_ms) = timed_frame(&mut full, f as u64, s.shot(p), &full_cfg)?;
            let (b, predicted_ms) = timed_frame(&mut pb, f as u64, s.shot(p), &cfg)?;
            let (x, y) = (&a.images[0], &b.images[0]);
            points.push(PredictionPoint {
                kappa,
                frame: f,
                full_ms,
                predicted_ms,
                predicted: b.predicted,
                differing: pixels_off(x, y, 1.0 / 255.0),
                identical: x == y,
                psnr_db: image_error(y, &as_reference(x)).psnr_db,
            });
        }
    }
    write_prediction_csv(&out.join("prediction.csv"), &points)?;
    Ok(points)
}

fn write_prediction_csv(path: &Path, points: &[PredictionPoint]) -> Result<()> {
    write_table(
        path,
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
    )
}

/// Prints, for each κ, the prediction buffer's speed-up and how far its
/// frames are from full traversal's.
pub fn print_prediction(s: &Sequence, script: &Path, isovalue: f64, points: &[PredictionPoint]) {
    println!(
        "{} frames of {} per κ, {}×{}, isovalue {isovalue}:",
        s.placements.len(),
        script.display(),
        s.view.resolution[0],
        s.view.resolution[1]
    );
    let mut kappas: Vec<[f64; 2]> = Vec::new();
    for p in points {
        if !kappas.contains(&p.kappa) {
            kappas.push(p.kappa);
        }
    }
    for k in kappas {
        let q: Vec<_> = points.iter().filter(|p| p.kappa == k).collect();
        let full: f64 = q.iter().map(|p| p.full_ms).sum();
        let pred: f64 = q.iter().map(|p| p.predicted_ms).sum();
        let steered: Vec<_> = q.iter().filter(|p| p.predicted).collect();
        let n = steered.len().max(1) as f64;
        let mean_diff = steered.iter().map(|p| p.differing).sum::<f64>() / n;
        let worst = steered.iter().map(|p| p.differing).fold(0.0, f64::max);
        let psnr = steered.iter().map(|p| p.psnr_db).sum::<f64>() / n;
        let fulls = q.iter().filter(|p| !p.predicted).count();
        let exact = q.iter().filter(|p| !p.predicted && p.identical).count();
        println!(
            "  κ {:?}: full traversal {:.1} ms/frame, prediction buffer {:.1} ms/frame: speed-up {:.2}×; \
             pixels differing by over 1/255 {:.2} % mean, {:.2} % worst, PSNR {psnr:.1} dB; periodic full traversals equal to full: {exact} of {fulls}",
            k,
            full / q.len() as f64,
            pred / q.len() as f64,
            full / pred,
            100.0 * mean_diff,
            100.0 * worst
        );
    }
}
