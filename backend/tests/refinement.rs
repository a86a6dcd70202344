//! Opaque-segment refinement (`render.refinement`): a segment whose own
//! optical depth exceeds 1 is marched again in parts, because where inside
//! it the opacity accrues is what the pixel shows, and the linear chord
//! that pre-integration assumes misplaces it. Its level-of-detail partner
//! (`render.opaque_detail`): a node whose voxel can be opaque is drawn one
//! level finer, because a coarser level moves the surface the pixel shows.
//! Measured against the exact integral; a function that cannot make such a
//! segment or voxel is left bit for bit as it was. Every test prints the
//! figures it asserts on.

mod support;
use parallax_backend::data;
use parallax_backend::reference::{self, Tolerance};
use parallax_backend::render::Renderer;
use parallax_backend::store::BrickEncoding;
use parallax_backend::volume::Volume;
use parallax_common::camera::View;
use parallax_common::config::RenderConfig;
use parallax_common::tf::TransferFunction;

/// The converged image and the samples its last frame took.
fn converged(
    db: &std::path::Path,
    tf: &TransferFunction,
    view: View,
    cfg: &RenderConfig,
) -> (Vec<[f32; 4]>, u64) {
    let (img, samples, _) = converged_cut(db, tf, view, cfg);
    (img, samples)
}

/// [`converged`] and the number of leaves with data in the last cut.
fn converged_cut(
    db: &std::path::Path,
    tf: &TransferFunction,
    view: View,
    cfg: &RenderConfig,
) -> (Vec<[f32; 4]>, u64, u64) {
    let mut r = Renderer::new(db, cfg).unwrap();
    r.count_samples = true;
    r.set_transfer_function(1, tf).unwrap();
    let f = r
        .converge(&support::ct_placement(), &[view], cfg, 64)
        .unwrap();
    (
        f.images[0].clone(),
        f.stats.samples,
        f.stats.cut_leaves_with_data,
    )
}

/// CT-Soft-Tissue and the exact integral of the CT phantom that
/// `support::ct_bone` wrote into `dir`, seen through `view`.
fn soft_tissue_exact(
    dir: &std::path::Path,
    view: &View,
) -> (TransferFunction, Vec<reference::Rgba>) {
    let soft = TransferFunction::load(support::configs().join("tf/ct-soft-tissue.toml")).unwrap();
    let vol = Volume::read_all(data::open(&dir.join("ct.nrrd"), None).unwrap().as_mut()).unwrap();
    let exact = reference::render(
        &vol,
        &soft,
        &support::ct_placement(),
        view,
        Tolerance { abs: 1e-6 },
    );
    (soft, exact)
}

/// The CT phantom seen from afar, its level-0 voxels about 0.8 px and its
/// level 1 about 1.6: `accuracy` 2 alone draws level 1, whose body
/// outline under CT-Soft-Tissue (opaque within a voxel) sits up to half a
/// level-1 voxel off. `opaque_detail` 2 draws the voxels that can be
/// opaque one level finer; the faint function's nodes, none of which can
/// be, keep their cut and their image bit for bit.
#[test]
fn opaque_voxels_are_drawn_one_level_finer() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let view = View::window([96, 96], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let (soft, exact) = soft_tissue_exact(dir.path(), &view);
    let at = |opaque_detail: f64| RenderConfig {
        opaque_detail,
        accuracy: 2.0,
        ..RenderConfig::default()
    };
    let mut errors = Vec::new();
    let mut leaves = Vec::new();
    for detail in [1.0, 2.0, 4.0] {
        let (img, samples, n) = converged_cut(&db, &soft, view, &at(detail));
        support::assert_valid("opaque detail", &img);
        let (e, max) = support::error(&img, &exact);
        println!(
            "opaque_detail {detail}: {n} leaves with data, {samples} samples, RMSE {e:.3e} (max {max:.3e}) against the exact integral"
        );
        errors.push(e);
        leaves.push(n);
    }
    assert!(leaves[1] > leaves[0], "one level finer: {leaves:?}");
    assert!(
        errors[1] < 0.75 * errors[0],
        "the outline where the exact integral has it: {errors:?}"
    );
    assert!(
        leaves[2] >= leaves[1] && errors[2] <= errors[1] * 1.05,
        "{leaves:?} {errors:?}"
    );

    // CT-Bone at a tenth of its extinction: no voxel of any level in view
    // can stop a ray, so the knob changes nothing.
    let faint = bone.scaled_extinction(0.1);
    let (a, _, na) = converged_cut(&db, &faint, view, &at(1.0));
    let (b, _, nb) = converged_cut(&db, &faint, view, &at(2.0));
    let same = a
        .iter()
        .zip(&b)
        .all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits));
    println!(
        "a faint function: {na} and {nb} leaves with data, the same image bit for bit: {same}"
    );
    assert_eq!(na, nb);
    assert!(same);
}

/// The CT phantom (full precision) under 3D Slicer's CT-Soft-Tissue, which
/// turns opaque within 7 HU (τ = 13.8/mm): at the default step one segment
/// across the phantom's noisy surface holds nearly all of a pixel's
/// opacity. Without refinement the default is 0.26 RMSE from the exact
/// integral; at most 2 parts cut it to 0.12, 4 (the default) to 3.7e-2,
/// 8 to 3.0e-2.
#[test]
fn refinement_brings_opaque_surfaces_to_the_exact_integral() {
    let dir = tempfile::tempdir().unwrap();
    let (db, _) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let view = View::window([48, 48], [0.03, 0.03], [0.0, 0.0, 0.8]);
    let (soft, exact) = soft_tissue_exact(dir.path(), &view);
    let mut errors = Vec::new();
    for parts in [1u32, 2, 4, 8] {
        let cfg = RenderConfig {
            refinement: parts,
            ..RenderConfig::default()
        };
        let (img, samples) = converged(&db, &soft, view, &cfg);
        support::assert_valid("refined", &img);
        let (e, max) = support::error(&img, &exact);
        println!("refinement {parts}: RMSE {e:.3e} (max {max:.3e}) against the exact integral, {samples} samples");
        errors.push(e);
    }
    assert!(
        errors[0] > 0.1,
        "the unrefined default misplaces the surface: {errors:?}"
    );
    assert!(
        errors[1] < 0.5 * errors[0] && errors[2] < 0.5 * errors[1],
        "{errors:?}"
    );
    // Eight parts reach only the segments thicker than 4 (⌈τ̄·h⌉ parts).
    assert!(errors[3] < errors[2], "{errors:?}");
    assert!(errors[2] < 4e-2, "{errors:?}");
}

/// A function whose largest extinction over the frame's longest step
/// cannot reach the refinement's depth (the kernel leaves it out) draws
/// the image it drew without refinement, bit for bit.
#[test]
fn refinement_is_left_out_where_no_segment_can_be_thick() {
    let dir = tempfile::tempdir().unwrap();
    let (db, bone) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let view = View::window([48, 48], [0.3, 0.3], [0.0, 0.0, 0.8]);
    // CT-Bone at a tenth of its extinction: at most 0.13/mm.
    let faint = bone.scaled_extinction(0.1);
    let off = RenderConfig {
        refinement: 1,
        ..RenderConfig::default()
    };
    let (a, _) = converged(&db, &faint, view, &off);
    let (b, _) = converged(&db, &faint, view, &RenderConfig::default());
    let same = a
        .iter()
        .zip(&b)
        .all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits));
    let lit = a.iter().filter(|p| p[3] > 0.01).count();
    println!(
        "a faint function: {lit} pixels lit, refined and unrefined the same bit for bit: {same}"
    );
    assert!(lit > 100, "the phantom is in view");
    assert!(same);
}

/// With early termination off, a ray goes on through the opaque body; the
/// segments behind the surface, where less than 1/256 of the light is
/// left, are not refined, so refinement adds about a surface's worth of
/// samples, not one for every thick segment of the ray.
#[test]
fn refinement_stops_behind_the_surface() {
    let dir = tempfile::tempdir().unwrap();
    let (db, _) = support::ct_bone(dir.path(), BrickEncoding::F32);
    let soft = TransferFunction::load(support::configs().join("tf/ct-soft-tissue.toml")).unwrap();
    let view = View::window([48, 48], [0.3, 0.3], [0.0, 0.0, 0.8]);
    let at = |refinement: u32| RenderConfig {
        refinement,
        early_termination: 1.0,
        ..RenderConfig::default()
    };
    let (_, plain) = converged(&db, &soft, view, &at(1));
    let (img, refined) = converged(&db, &soft, view, &at(8));
    let lit = img.iter().filter(|p| p[3] > 0.5).count() as u64;
    let extra = refined as f64 - plain as f64;
    println!(
        "early termination off: {plain} samples unrefined, {refined} with 8 parts ({:.1} more a lit pixel, {lit} lit)",
        extra / lit as f64
    );
    assert!(lit > 100, "the phantom is in view");
    assert!(refined > plain, "the surfaces are refined");
    // A refined surface costs its 7 extra samples and the segment's own;
    // refining every thick segment behind it would cost hundreds a ray.
    assert!(
        extra / (lit as f64) < 40.0,
        "{extra} extra samples over {lit} pixels"
    );
}
