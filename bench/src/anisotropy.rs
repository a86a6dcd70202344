//! `parallax bench anisotropy`: the level of detail on thick slices.

use crate::measure::{
    converged, create_out, precise_config, precise_step, timed_frame, write_table, Shot,
    CONVERGE_FRAMES, FULL_DETAIL,
};
use anyhow::Result;
use parallax_backend::data::synth::{coord, shepp_logan};
use parallax_backend::metric::image_error;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::store::{self, BrickEncoding, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Interpolation, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;
use std::time::Instant;

/// One volume and view of the study.
#[derive(Clone, Debug)]
pub struct AnisotropyPoint {
    pub volume: &'static str,
    pub spacing: [f64; 3],
    pub dims: [usize; 3],
    /// "near", "far" (the volume four times smaller on screen), or
    /// "axial" (near, seen along the slices' normal: its rays cross the
    /// thick edge).
    pub view: &'static str,
    pub accuracy: f64,
    /// Multilevel sampling (G10 §4) on.
    pub multilevel: bool,
    pub rmse: f64,
    pub max_abs: f64,
    pub bricks: u64,
    pub frame_ms: f64,
    /// Samples the frame took (counted on the axial view only, whose
    /// frame time then includes the counting; 0 elsewhere).
    pub samples: u64,
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
/// and grandparent across the split axes), with every other knob precise
/// (full-precision bricks, exact interpolation, step 1/4, no early
/// termination), and compared with its own exact integral: the difference
/// between the two accuracies is what the level of detail costs. Writes
/// `anisotropy.csv`.
pub fn run_anisotropy(out: &Path) -> Result<Vec<AnisotropyPoint>> {
    anisotropy_study(out, 256, [256, 192], 0.25)
}

/// The accuracies the thick slices are swept over.
pub const ACCURACY_SWEEP: [f64; 7] = [0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

/// (name, isotropic levels, (accuracy, multilevel) renders) of each import
/// of a volume.
type Imports = Vec<(&'static str, bool, Vec<(f64, bool)>)>;

/// The study's volumes: (name, dims, spacing, imports) on a cube of `mm`
/// millimetres.
fn volumes(mm: usize, default: f64) -> [(&'static str, [usize; 3], [f64; 3], Imports); 3] {
    [
        (
            "isotropic 1 mm",
            [mm, mm, mm],
            [1.0, 1.0, 1.0],
            vec![(
                "isotropic 1 mm",
                false,
                vec![(default, false), (default, true)],
            )],
        ),
        // The thick slices' in-plane detail, isotropic: what their level of
        // detail does in-plane is what it does here.
        (
            "isotropic 0.5 mm",
            [2 * mm, 2 * mm, 2 * mm],
            [0.5, 0.5, 0.5],
            vec![(
                "isotropic 0.5 mm",
                false,
                vec![(default, false), (default, true)],
            )],
        ),
        (
            "0.5 x 0.5 x 4 mm slices",
            [2 * mm, 2 * mm, mm / 4],
            [0.5, 0.5, 4.0],
            vec![
                (
                    "0.5 x 0.5 x 4 mm slices",
                    false,
                    // The default, full detail, multilevel, and `accuracy`
                    // from 0.25 to 16 (the knob must move every level).
                    [(default, false), (FULL_DETAIL, false), (default, true)]
                        .into_iter()
                        .chain(
                            ACCURACY_SWEEP
                                .iter()
                                .filter(|&&a| a != default)
                                .map(|&a| (a, false)),
                        )
                        .collect(),
                ),
                (
                    "0.5 x 0.5 x 4 mm slices (levels halving all axes)",
                    true,
                    vec![(default, false)],
                ),
            ],
        ),
    ]
}

fn ct_tf() -> Result<TransferFunction> {
    TransferFunction::from_points(vec![
        ControlPoint::new(0.0, [0.0; 3], 0.0),
        ControlPoint::new(40.0, [0.0; 3], 0.0),
        ControlPoint::new(150.0, [0.9, 0.55, 0.35], 0.01),
        ControlPoint::new(400.0, [0.9, 0.85, 0.7], 0.04),
        ControlPoint::new(1000.0, [1.0; 3], 0.2),
    ])
}

fn placement(size: f64, axial: bool) -> Placement {
    Placement {
        center: [0.0, 0.0, 0.0],
        // Axial: the volume's z (the slices' normal) 7° off the view axis.
        rotation_deg: if axial {
            [5.0, 5.0, 0.0]
        } else {
            [-70.0, 25.0, 0.0]
        },
        size,
    }
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
    create_out(out)?;
    let tf = ct_tf()?;
    let view = View::window(resolution, [0.4, 0.3], [0.0, 0.0, 0.8]);
    let views = [
        ("near", size, false),
        ("far", size / 4.0, false),
        ("axial", size, true),
    ];
    let tmp = tempfile::tempdir()?;
    let mut points = Vec::new();
    let default = RenderConfig::default().accuracy;
    for (vname, dims, spacing, imports) in volumes(mm, default) {
        let vol = Volume::from_fn(dims, spacing, VoxelType::U16, |i, j, k| {
            (1000.0 * shepp_logan([coord(i, dims[0]), coord(j, dims[1]), coord(k, dims[2])]))
                .round() as f32
        });
        let references: Vec<Vec<[f64; 4]>> = views
            .iter()
            .map(|&(vw, sz, axial)| {
                let t = Instant::now();
                let r = reference::render(
                    &vol,
                    &tf,
                    &placement(sz, axial),
                    &view,
                    Tolerance { abs: 1e-6 },
                );
                eprintln!(
                    "{vname}, {vw}: reference integral {:.1} s",
                    t.elapsed().as_secs_f64()
                );
                r
            })
            .collect();
        for (name, isotropic_levels, accuracies) in imports {
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
            for (&(vw, sz, axial), reference) in views.iter().zip(&references) {
                let shot = Shot {
                    db: &db,
                    tf: &tf,
                    placement: &placement(sz, axial),
                    view: &view,
                };
                for &(accuracy, multilevel) in &accuracies {
                    // The axial view at the default settings only.
                    if axial && (multilevel || accuracy != default) {
                        continue;
                    }
                    let p = measure(shot, reference, accuracy, multilevel, axial)?;
                    let p = AnisotropyPoint {
                        volume: name,
                        spacing,
                        dims,
                        view: vw,
                        ..p
                    };
                    eprintln!(
                        "{name:>50}, {vw:>5}, accuracy {accuracy:<5}{}: RMSE {:.2e}, max {:.2e}, {} bricks, {:.0} ms{}",
                        if multilevel { ", multilevel" } else { "" },
                        p.rmse,
                        p.max_abs,
                        p.bricks,
                        p.frame_ms,
                        if axial { format!(", {} samples", p.samples) } else { String::new() }
                    );
                    points.push(p);
                }
            }
        }
    }
    write_csv(out, &points)?;
    summarize(&points, default);
    Ok(points)
}

/// One render of `shot` against its exact integral.
fn measure(
    shot: Shot,
    reference: &[[f64; 4]],
    accuracy: f64,
    multilevel: bool,
    count_samples: bool,
) -> Result<AnisotropyPoint> {
    let cfg = RenderConfig {
        accuracy,
        multilevel,
        interpolation: Interpolation::Exact,
        step_factor: precise_step(accuracy),
        ..precise_config()
    };
    let (mut r, _) = converged(shot, &cfg, &[], CONVERGE_FRAMES)?;
    r.count_samples = count_samples;
    let (f, frame_ms) = timed_frame(&mut r, 100, shot, &cfg)?;
    let e = image_error(&f.images[0], reference);
    Ok(AnisotropyPoint {
        volume: "",
        spacing: [0.0; 3],
        dims: [0; 3],
        view: "",
        accuracy,
        multilevel,
        rmse: e.rmse,
        max_abs: e.max_abs,
        bricks: f.stats.cut_leaves_with_data,
        frame_ms,
        samples: f.stats.samples,
    })
}

fn write_csv(out: &Path, points: &[AnisotropyPoint]) -> Result<()> {
    write_table(
        &out.join("anisotropy.csv"),
        "volume,spacing_mm,dims,view,accuracy,multilevel,rmse,max_abs,bricks_in_cut,frame_ms,samples",
        points.iter().map(|p| {
            let [sx, sy, sz] = p.spacing;
            let [nx, ny, nz] = p.dims;
            format!(
                "{},{sx}x{sy}x{sz},{nx}x{ny}x{nz},{},{},{},{:.6e},{:.6e},{},{:.1},{}",
                p.volume,
                p.view,
                p.accuracy,
                p.multilevel,
                p.rmse,
                p.max_abs,
                p.bricks,
                p.frame_ms,
                p.samples
            )
        }),
    )
}

/// Prints the thick slices' error against the isotropic one's, each view.
fn summarize(points: &[AnisotropyPoint], default: f64) {
    for vw in ["near", "far", "axial"] {
        let at_default = |v: &str| {
            points
                .iter()
                .find(|p| p.volume == v && p.view == vw && p.accuracy == default && !p.multilevel)
                .map(|p| (p.rmse, p.bricks))
                .unwrap_or((f64::NAN, 0))
        };
        let iso = at_default("isotropic 0.5 mm");
        let fitted = at_default("0.5 x 0.5 x 4 mm slices");
        let all = at_default("0.5 x 0.5 x 4 mm slices (levels halving all axes)");
        eprintln!(
            "{vw}: thick slices / isotropic 0.5 mm error at the default accuracy: {:.2} ({} bricks; \
             levels halving all axes: {:.2}, {} bricks)",
            fitted.0 / iso.0,
            fitted.1,
            all.0 / iso.0,
            all.1
        );
    }
}
