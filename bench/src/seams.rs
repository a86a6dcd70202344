//! `parallax bench seams`: steps at level changes, one level of detail per
//! brick against multilevel sampling (G10 §4, Fig. 5).

use crate::measure::{
    converged_frame, create_out, precise_config, precise_step, write_table, Shot, FULL_DETAIL,
};
use anyhow::Result;
use parallax_backend::metric::image_error;
use parallax_backend::output::write_png;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::store::{self, BrickEncoding, ImportOptions};
use parallax_backend::volume::{MemorySource, Volume, VoxelType};
use parallax_common::camera::{Placement, View};
use parallax_common::config::{Interpolation, RenderConfig};
use parallax_common::tf::{ControlPoint, TransferFunction};
use std::path::Path;

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

/// A thin slab of a smooth field seen face-on from close by, so that the
/// cut holds finer bricks at the centre than at the edges, rendered with
/// one level of detail per brick and with multilevel sampling (G10 §4,
/// Fig. 5). Writes `seams.csv` and the images.
pub fn run_seams(out: &Path) -> Result<Vec<SeamPoint>> {
    seam_study(out, 128, [384, 288])
}

/// An image, the leaves with data in its cut and its frame time (ms).
type Render = (Vec<[f32; 4]>, u64, f64);

/// [`run_seams`] on an n × n × n/8 slab at `resolution` (n / width fixed
/// at 2/3 keeps the levels where they are: a leaf voxel about a pixel at
/// the centre, two at the corners).
pub fn seam_study(out: &Path, n: usize, resolution: [u32; 2]) -> Result<Vec<SeamPoint>> {
    create_out(out)?;
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
    let shot = Shot {
        db: &db,
        tf: &tf,
        placement: &placement,
        view: &view,
    };
    let render = |accuracy: f64, multilevel: bool| -> Result<Render> {
        let cfg = RenderConfig {
            accuracy,
            multilevel,
            interpolation: Interpolation::Exact,
            step_factor: precise_step(accuracy),
            // The step at a level change is the levels' data; the opaque
            // segments' refinement alone takes it from 9.5e-3 to 1.3e-3
            // here (each level's chord error is most of it), so it is off.
            refinement: 1,
            // Every node to `accuracy`, so that the cut mixes levels where
            // the footprint says (opaque voxels one level finer would make
            // this view's cut all level 0: no seam to study).
            opaque_detail: 1.0,
            ..precise_config()
        };
        let (f, ms) = converged_frame(shot, &cfg)?;
        Ok((f.images[0].clone(), f.stats.cut_leaves_with_data, ms))
    };
    let (full, _, _) = render(FULL_DETAIL, false)?;
    let interior = interior(&full, resolution);
    let mut points = Vec::new();
    for accuracy in [4.0, 8.0] {
        let before = render(accuracy, false)?;
        let after = render(accuracy, true)?;
        for (name, img) in [("one-level", &before.0), ("multilevel", &after.0)] {
            write_png(
                &out.join(format!("seams-accuracy{accuracy}-{name}.png")),
                resolution[0],
                resolution[1],
                img,
            )?;
        }
        let (pairs, jump_before, jump_after) = jumps(
            &full,
            &before.0,
            &after.0,
            &interior,
            resolution[0] as usize,
        );
        let p = SeamPoint {
            accuracy,
            seam_pairs: pairs,
            jump_before,
            jump_after,
            rmse_before: image_error(&before.0, &reference).rmse,
            rmse_after: image_error(&after.0, &reference).rmse,
            bricks: before.1,
            bricks_after: after.1,
            ms_before: before.2,
            ms_after: after.2,
        };
        eprintln!("accuracy {accuracy}: {}", p.summary());
        points.push(p);
    }
    write_csv(out, &points)?;
    Ok(points)
}

/// Pixels whose 5 × 5 neighbourhood lies inside the volume's image in
/// `full`: at the silhouette the rays leave through the sides, which is no
/// seam.
fn interior(full: &[[f32; 4]], [w, h]: [u32; 2]) -> Vec<bool> {
    let (w, h) = (w as usize, h as usize);
    (0..w * h)
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
        .collect()
}

/// Across the neighbouring interior pixel pairs where `before` (one level
/// per brick) changes from full detail to a coarser level: their count,
/// and the largest excess step over `full`'s in `before` and in `after`.
fn jumps(
    full: &[[f32; 4]],
    before: &[[f32; 4]],
    after: &[[f32; 4]],
    interior: &[bool],
    w: usize,
) -> (usize, f64, f64) {
    // A ray that met full-detail bricks only (or that a coarse brick
    // changed by less than 1e-4) against one that a coarse one changed.
    let exact =
        |i: usize| (0..4).all(|c| ((before[i][c] as f64) - (full[i][c] as f64)).abs() < 1e-4);
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
    for i in 0..before.len() {
        for j in [i + 1, i + w] {
            if (j == i + 1 && j % w == 0)
                || j >= before.len()
                || !interior[i]
                || !interior[j]
                || exact(i) == exact(j)
            {
                continue;
            }
            pairs += 1;
            jump_before = jump_before.max(step(before, i, j));
            jump_after = jump_after.max(step(after, i, j));
        }
    }
    (pairs, jump_before, jump_after)
}

impl SeamPoint {
    /// The point in words.
    fn summary(&self) -> String {
        let SeamPoint {
            bricks,
            bricks_after,
            seam_pairs,
            jump_before,
            jump_after,
            rmse_before,
            rmse_after,
            ms_before,
            ms_after,
            ..
        } = self;
        format!(
            "{bricks} → {bricks_after} bricks, {seam_pairs} pixel pairs across level changes; \
             largest step there {jump_before:.2e} with one level per brick, {jump_after:.2e} with \
             multilevel sampling; RMSE {rmse_before:.2e} → {rmse_after:.2e}; {ms_before:.0} → \
             {ms_after:.0} ms"
        )
    }
}

fn write_csv(out: &Path, points: &[SeamPoint]) -> Result<()> {
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
    )
}
