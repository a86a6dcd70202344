//! The CPU pick behind the live coordinator's focus action: which point of
//! the volume a click hits, so that the point can be moved onto the screen
//! plane.
//!
//! A coarse copy of the volume (one octree level, at most about 64³ voxels,
//! read once from the database) is held in memory; a display-space ray is
//! moved to volume space, clipped to the volume's box and marched through the
//! copy at half a coarse voxel, the optical depth ∫τ summed by the trapezoid
//! rule under the transfer function. The hit is the first point where the
//! accumulated opacity 1 − exp(−∫τ) reaches a threshold (½ for a click).
//!
//! The copy follows the renderer's conventions: a level-l voxel i has its
//! centre at (i+½)·2^(L−l)·s, the field is the trilinear interpolant of the
//! level's voxels clamped to its edge voxels, no-data voxels (NaN) are left
//! out of the interpolation and count as transparent, and rays are clipped to
//! the volume's box [0, N·s] (data length units).

use crate::reference::clip_to_box;
use crate::store::{NodeKey, OctreeDb};
use crate::volume::{Volume, VolumeInfo, VoxelType};
use glam::DVec3;
use parallax_common::camera::Placement;
use parallax_common::tf::TransferFunction;

/// Voxels of the coarse copy the renderer reads for its picks (64³).
pub const PICK_VOXELS: usize = 64 * 64 * 64;

/// The accumulated opacity at which a click hits (½).
pub const PICK_THRESHOLD: f64 = 0.5;

/// Sub-steps a step is marched again in when the threshold is crossed in it
/// (a sharp transfer function ramps from clear to opaque within one step).
const REFINE: usize = 8;

/// Most steps along one ray (a bound on the work of an absurdly anisotropic
/// volume; the steps grow beyond it).
const MAX_STEPS: usize = 1 << 20;

/// A coarse copy of the volume (one octree level, at most about 64³ voxels,
/// read once from the database) that rays are marched through on the CPU.
pub struct PickVolume {
    /// The level's voxel grid as a volume whose voxels are the level's
    /// (spacing 2^(L−l)·s): its `sample` is the level's trilinear field.
    grid: Volume,
    /// Which octree level the copy is of.
    level: u32,
    /// The database volume's extent N·s (data length units): the box rays
    /// are clipped to, and what [`Placement`] maps.
    extent: [f64; 3],
}

impl PickVolume {
    /// Reads the finest level of the database whose whole grid has at most
    /// `max_voxels` voxels (the root level when none has), decoding its
    /// bricks into one array.
    ///
    /// Stored bricks give their own voxels. A node that is not stored (all
    /// its values no data, or all below the import's `--empty-below`) is what
    /// the renderer skips: its voxels are no data (NaN), except those that a
    /// stored neighbour's overlap holds, which take the values stored there,
    /// so the field inside a stored brick up to its faces is the one the
    /// renderer interpolates. A brick that fails to read or decode is
    /// reported and treated as not stored (as the loader does, it is not
    /// fatal).
    pub fn from_db(db: &OctreeDb, max_voxels: usize) -> anyhow::Result<PickVolume> {
        let layout = *db.layout();
        let level = (0..layout.levels)
            .rev()
            .find(|&l| layout.level_dims(l).iter().product::<usize>() <= max_voxels)
            .unwrap_or(0);
        let dims = layout.level_dims(level);
        let [nx, ny, nz] = dims;
        let scale = layout.voxel_scale(level);
        let spacing = db.header.info.spacing;
        let nb = layout.level_bricks(level);
        let b = layout.brick;
        let side = layout.stored_side();
        let key_of = |bx: usize, by: usize, bz: usize| {
            NodeKey::new(level as u8, bx as u32, by as u32, bz as u32)
        };
        let brick_index = |bx: usize, by: usize, bz: usize| (bz * nb[1] + by) * nb[0] + bx;

        // Every stored brick of the level, decoded (None: not stored, or
        // unreadable).
        let mut bricks: Vec<Option<Vec<f32>>> = Vec::with_capacity(nb[0] * nb[1] * nb[2]);
        for bz in 0..nb[2] {
            for by in 0..nb[1] {
                for bx in 0..nb[0] {
                    let key = key_of(bx, by, bz);
                    let stored = db.node(key).is_some_and(|r| r.is_stored());
                    let values = if stored {
                        match db.read_brick(key) {
                            Ok(Some(v)) if v.len() == side * side * side => Some(v),
                            Ok(Some(v)) => {
                                tracing::warn!(
                                    "pick volume: brick {key} decoded to {} values, not {}: its voxels count as no data",
                                    v.len(),
                                    side * side * side
                                );
                                None
                            }
                            Ok(None) => None,
                            Err(e) => {
                                tracing::warn!("pick volume: {e:#}: its voxels count as no data");
                                None
                            }
                        }
                    } else {
                        None
                    };
                    bricks.push(values);
                }
            }
        }

        let mut data = vec![f32::NAN; nx * ny * nz];
        for bz in 0..nb[2] {
            for by in 0..nb[1] {
                for bx in 0..nb[0] {
                    let Some(values) = &bricks[brick_index(bx, by, bz)] else {
                        continue;
                    };
                    let o = layout.brick_origin(key_of(bx, by, bz));
                    // The brick's local indices that fall inside the grid.
                    let inside = |axis: usize| {
                        let lo = (-o[axis]).clamp(0, side as i64) as usize;
                        let hi = (dims[axis] as i64 - o[axis]).clamp(0, side as i64) as usize;
                        lo..hi.max(lo)
                    };
                    for c in inside(2) {
                        let z = (o[2] + c as i64) as usize;
                        for r in inside(1) {
                            let y = (o[1] + r as i64) as usize;
                            for a in inside(0) {
                                let x = (o[0] + a as i64) as usize;
                                let owner = (x / b, y / b, z / b);
                                // Its own voxels, and the overlap that lies in
                                // a brick with no values of its own.
                                let own = owner == (bx, by, bz);
                                if own || bricks[brick_index(owner.0, owner.1, owner.2)].is_none() {
                                    let v = values[(c * side + r) * side + a];
                                    data[(z * ny + y) * nx + x] = v;
                                }
                            }
                        }
                    }
                }
            }
        }

        let grid = Volume::new(
            VolumeInfo {
                dims,
                spacing: std::array::from_fn(|a| spacing[a] * scale[a] as f64),
                voxel_type: VoxelType::F32,
            },
            data,
        );
        Ok(PickVolume {
            grid,
            level,
            extent: db.header.info.extent(),
        })
    }

    /// The octree level the copy is of.
    pub fn level(&self) -> u32 {
        self.level
    }

    /// The copy's voxel grid.
    pub fn dims(&self) -> [usize; 3] {
        self.grid.info.dims
    }

    /// The volume's extent N·s (data length units).
    pub fn extent(&self) -> [f64; 3] {
        self.extent
    }

    /// The march step: half the smallest side of a coarse voxel (data
    /// length units).
    pub fn step(&self) -> f64 {
        0.5 * self
            .grid
            .info
            .spacing
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
    }

    /// The first point along the display-space ray origin + t·dir (t ≥ 0)
    /// where the accumulated opacity 1 − exp(−∫τ) reaches `threshold` (0.5
    /// by the caller), in display space; None when the ray misses the
    /// volume's box or never reaches it.
    ///
    /// The ray is marched through the box in steps of at most half a coarse
    /// voxel (data length units, as the renderer measures extinction), the
    /// field sampled trilinearly, the optical depth summed by the trapezoid
    /// rule; the step in which the depth reaches −ln(1 − threshold) is
    /// marched again in 8 sub-steps and the crossing interpolated
    /// linearly within the sub-step. No-data samples are transparent. A
    /// threshold ≤ 0 hits where the ray enters the box; one ≥ 1 (or NaN)
    /// never hits.
    pub fn pick(
        &self,
        tf: &TransferFunction,
        placement: &Placement,
        origin: [f64; 3],
        dir: [f64; 3],
        threshold: f64,
    ) -> Option<[f64; 3]> {
        let (o, d) = (DVec3::from(origin), DVec3::from(dir));
        if !(o.is_finite() && d.is_finite()) || d.length_squared() == 0.0 {
            return None;
        }
        if threshold.is_nan() || threshold >= 1.0 {
            return None;
        }
        let (vo, vd) = placement.ray_to_volume(self.extent, o, d);
        if !(vo.is_finite() && vd.is_finite()) {
            return None;
        }
        let (t0, t1) = clip_to_box(vo, vd, DVec3::from(self.extent))?;
        // Opacity θ is reached at optical depth −ln(1 − θ).
        let target = -f64::ln_1p(-threshold.max(0.0));
        let tau_at = |t: f64| -> f64 {
            let v = self.grid.sample((vo + vd * t).into());
            if v.is_nan() {
                0.0
            } else {
                tf.tau(v)
            }
        };
        let span = t1 - t0;
        let h = self.step();
        let n = if h > 0.0 && (span / h).is_finite() {
            ((span / h).ceil() as usize).clamp(1, MAX_STEPS)
        } else {
            1
        };
        let mut depth = 0.0;
        let t = march(&tau_at, t0, t1, n, &mut depth, target, true)?;
        let p = placement.to_display(self.extent, vo + vd * t);
        p.is_finite().then_some(p.to_array())
    }
}

/// Most voxels a region grows to (the whole 64³ copy is 2^18).
pub const GROW_MAX_VOXELS: usize = 1 << 20;

impl PickVolume {
    /// A band picker's band grown from a point (G10 §4 band picker "grown
    /// from a picked point", after G10's reference [11], RGVis: region
    /// growing): from the copy's voxel holding `seed` (volume space, data
    /// length units) the 6-connected voxels whose values lie within
    /// `tolerance` (data values) of the seed voxel's join the region, up to
    /// [`GROW_MAX_VOXELS`]. The band's feet are the region's least and
    /// greatest values, its plateau their 10th and 90th percentiles, so it
    /// covers the material the point lies in and little else. None where
    /// the seed lies outside the box or on no data.
    pub fn grow_band(&self, seed: DVec3, tolerance: f64) -> Option<[f64; 4]> {
        let dims = self.grid.info.dims;
        let sp = self.grid.info.spacing;
        if !(seed.is_finite() && tolerance.is_finite() && tolerance >= 0.0) {
            return None;
        }
        let mut at = [0usize; 3];
        for a in 0..3 {
            let i = (seed[a] / sp[a]).floor();
            if !(0.0..dims[a] as f64).contains(&i) {
                return None;
            }
            at[a] = i as usize;
        }
        let index = |v: [usize; 3]| (v[2] * dims[1] + v[1]) * dims[0] + v[0];
        let data = &self.grid.data;
        let s0 = data[index(at)] as f64;
        if s0.is_nan() {
            return None;
        }
        let mut seen = vec![false; data.len()];
        let mut queue = std::collections::VecDeque::from([at]);
        seen[index(at)] = true;
        let mut values = Vec::new();
        while let Some(v) = queue.pop_front() {
            values.push(data[index(v)] as f64);
            if values.len() >= GROW_MAX_VOXELS {
                break;
            }
            for (a, step) in [(0, -1i64), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)] {
                let c = v[a] as i64 + step;
                if c < 0 || c >= dims[a] as i64 {
                    continue;
                }
                let mut n = v;
                n[a] = c as usize;
                let k = index(n);
                if seen[k] {
                    continue;
                }
                let x = data[k] as f64;
                if !x.is_nan() && (x - s0).abs() <= tolerance {
                    seen[k] = true;
                    queue.push_back(n);
                }
            }
        }
        values.sort_by(f64::total_cmp);
        let q = |f: f64| values[((values.len() - 1) as f64 * f).round() as usize];
        let (mut lo, mut hi) = (values[0], values[values.len() - 1]);
        if hi <= lo {
            // A region of one value: a band as wide as the tolerance (or a
            // millionth of the value) about it.
            let w = (0.5 * tolerance).max(1e-6 * s0.abs()).max(1e-9);
            lo -= w;
            hi += w;
        }
        Some([lo, q(0.1).max(lo), q(0.9).min(hi), hi])
    }
}

/// Marches [a, b] in `n` equal steps from the optical depth `*depth`, adding
/// each step's depth by the trapezoid rule in τ. Returns the t where the
/// depth reaches `target`, or None with `*depth` advanced to b. With
/// `refine`, the step where it does is marched again in [`REFINE`] sub-steps
/// (if they do not reach it after all, the march goes on with their depth);
/// without, the crossing is interpolated linearly within the step.
fn march(
    tau_at: &dyn Fn(f64) -> f64,
    a: f64,
    b: f64,
    n: usize,
    depth: &mut f64,
    target: f64,
    refine: bool,
) -> Option<f64> {
    let n = n.max(1);
    let mut ta = a;
    let mut tau_a = tau_at(a);
    for k in 1..=n {
        let tb = if k == n {
            b
        } else {
            a + (b - a) * (k as f64 / n as f64)
        };
        let tau_b = tau_at(tb);
        let delta = 0.5 * (tau_a + tau_b) * (tb - ta);
        if *depth + delta >= target {
            if refine {
                let mut sub = *depth;
                if let Some(t) = march(tau_at, ta, tb, REFINE, &mut sub, target, false) {
                    return Some(t);
                }
                *depth = sub;
            } else {
                let f = if delta > 0.0 {
                    ((target - *depth) / delta).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                return Some(ta + f * (tb - ta));
            }
        } else {
            *depth += delta;
        }
        ta = tb;
        tau_a = tau_b;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{self, ImportOptions};
    use crate::volume::MemorySource;
    use parallax_common::tf::ControlPoint;
    use std::path::Path;

    const N: usize = 40;

    /// Centre (0, 0, 0), no rotation, 0.4 m for the 40-unit box: 0.01 m per
    /// data unit (1 mm voxels); volume z = 20 + display z / 0.01.
    fn placement() -> Placement {
        Placement {
            center: [0.0; 3],
            rotation_deg: [0.0; 3],
            size: 0.4,
        }
    }

    const SCALE: f64 = 0.01;

    fn import(vol: &Volume, dir: &Path, name: &str, empty_below: Option<f32>) -> OctreeDb {
        let path = dir.join(name);
        store::import(
            &mut MemorySource::new(vol),
            &path,
            "test volume",
            &ImportOptions {
                brick: 8,
                empty_below,
                ..Default::default()
            },
        )
        .unwrap();
        OctreeDb::open(&path).unwrap()
    }

    /// 200 in the slab of voxels 12 ≤ k < 28 (z from 12 to 28), `above`
    /// from k = 32 up, 0 elsewhere.
    fn slab(above: f32) -> Volume {
        Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |_, _, k| {
            if (12..28).contains(&k) {
                200.0
            } else if k >= 32 {
                above
            } else {
                0.0
            }
        })
    }

    /// 200 inside the sphere of radius 10 about the centre (20, 20, 20).
    fn sphere() -> Volume {
        Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |i, j, k| {
            let d = |i: usize| i as f64 + 0.5 - 20.0;
            if d(i) * d(i) + d(j) * d(j) + d(k) * d(k) < 100.0 {
                200.0
            } else {
                0.0
            }
        })
    }

    /// Clear below 100, extinction 1000 per unit above 110.
    fn opaque_above_100() -> TransferFunction {
        TransferFunction::from_points(vec![
            ControlPoint::new(100.0, [1.0; 3], 0.0),
            ControlPoint::new(110.0, [1.0; 3], 1000.0),
        ])
        .unwrap()
    }

    fn transparent() -> TransferFunction {
        TransferFunction::from_points(vec![ControlPoint::new(0.0, [1.0; 3], 0.0)]).unwrap()
    }

    const DOWN: [f64; 3] = [0.0, 0.0, -1.0];

    fn assert_finite(p: Option<[f64; 3]>) {
        if let Some(p) = p {
            assert!(p.iter().all(|v| v.is_finite()), "{p:?}");
        }
    }

    /// The hit of a ray along −z from (x, 0, 1) m, which must exist.
    fn hit(pv: &PickVolume, tf: &TransferFunction, x: f64) -> [f64; 3] {
        let p = pv.pick(tf, &placement(), [x, 0.0, 1.0], DOWN, PICK_THRESHOLD);
        assert_finite(p);
        p.unwrap_or_else(|| panic!("the ray at x = {x} m misses"))
    }

    #[test]
    fn the_finest_level_that_fits_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let db = import(&slab(0.0), dir.path(), "slab.pxo", None);
        // bricks of 8 over 40 voxels: levels 0..=3, level 3 is 40³.
        assert_eq!(db.layout().levels, 4);
        let fine = PickVolume::from_db(&db, PICK_VOXELS).unwrap();
        assert_eq!((fine.level(), fine.dims()), (3, [40; 3]));
        let coarse = PickVolume::from_db(&db, 20 * 20 * 20).unwrap();
        assert_eq!((coarse.level(), coarse.dims()), (2, [20; 3]));
        assert_eq!(coarse.step(), 1.0);
        let root = PickVolume::from_db(&db, 1).unwrap();
        assert_eq!((root.level(), root.dims()), (0, [5; 3]));
        assert_eq!(fine.extent(), [40.0; 3]);
    }

    #[test]
    fn a_ray_down_the_axis_hits_the_slab_front_face() {
        let dir = tempfile::tempdir().unwrap();
        let tf = opaque_above_100();
        // The field crosses 100–110 just below z = 28 (display z 0.08).
        let want = (28.0 - 20.0) * SCALE;
        let cases = [
            ("plain", slab(0.0), None),
            ("empty bricks dropped", slab(0.0), Some(50.0f32)),
            ("no data above", slab(f32::NAN), None),
            (
                "no data above, empty bricks dropped",
                slab(f32::NAN),
                Some(50.0f32),
            ),
        ];
        for (i, (what, vol, empty_below)) in cases.into_iter().enumerate() {
            let db = import(&vol, dir.path(), &format!("slab{i}.pxo"), empty_below);
            if empty_below.is_some() {
                assert!(
                    db.nodes.iter().any(|n| !n.is_stored()),
                    "{what}: some brick is dropped"
                );
            }
            for (max_voxels, voxel) in [(PICK_VOXELS, 1.0), (20 * 20 * 20, 2.0)] {
                let pv = PickVolume::from_db(&db, max_voxels).unwrap();
                let centre = pv.grid.sample([20.0, 20.0, 20.0]);
                assert!(
                    (centre - 200.0).abs() < 1e-3,
                    "{what}: {centre} in the slab"
                );
                for x in [0.0, 0.05, -0.13] {
                    let p = hit(&pv, &tf, x);
                    assert!(
                        (p[2] - want).abs() <= 0.5 * voxel * SCALE,
                        "{what}, level {}: x {x}: hit at z {} m, want {want}",
                        pv.level(),
                        p[2]
                    );
                    assert!(
                        (p[0] - x).abs() < 1e-9 && p[1].abs() < 1e-9,
                        "{what}: {p:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_ray_down_the_axis_hits_the_sphere_front() {
        let dir = tempfile::tempdir().unwrap();
        let db = import(&sphere(), dir.path(), "sphere.pxo", None);
        let tf = opaque_above_100();
        for (max_voxels, voxel) in [(PICK_VOXELS, 1.0), (20 * 20 * 20, 2.0)] {
            let pv = PickVolume::from_db(&db, max_voxels).unwrap();
            // Through the centre the surface is at z = 30; 6 units off it,
            // at z = 20 + √(100 − 36) = 28.
            for (x, z) in [(0.0, 30.0), (6.0 * SCALE, 28.0)] {
                let want = (z - 20.0) * SCALE;
                let p = hit(&pv, &tf, x);
                assert!(
                    (p[2] - want).abs() <= voxel * SCALE,
                    "level {}: x {x}: hit at z {} m, want {want}",
                    pv.level(),
                    p[2]
                );
            }
            // Beside the sphere, inside the box: nothing.
            let p = pv.pick(&tf, &placement(), [0.15, 0.0, 1.0], DOWN, PICK_THRESHOLD);
            assert_eq!(p, None);
        }
    }

    #[test]
    fn misses_transparency_and_rays_from_inside() {
        let dir = tempfile::tempdir().unwrap();
        let db = import(&slab(f32::NAN), dir.path(), "slab.pxo", None);
        let pv = PickVolume::from_db(&db, PICK_VOXELS).unwrap();
        let (tf, pl) = (opaque_above_100(), placement());
        // Outside the box (it spans ±0.2 m).
        assert_eq!(pv.pick(&tf, &pl, [0.5, 0.0, 1.0], DOWN, 0.5), None);
        assert_eq!(pv.pick(&tf, &pl, [0.0, -0.25, 1.0], DOWN, 0.5), None);
        // The box lies behind the ray.
        assert_eq!(
            pv.pick(&tf, &pl, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 0.5),
            None
        );
        // Nothing is opaque.
        assert_eq!(
            pv.pick(&transparent(), &pl, [0.0, 0.0, 1.0], DOWN, 0.5),
            None
        );
        // Degenerate input.
        assert_eq!(pv.pick(&tf, &pl, [0.0, 0.0, 1.0], [0.0; 3], 0.5), None);
        assert_eq!(pv.pick(&tf, &pl, [f64::NAN, 0.0, 1.0], DOWN, 0.5), None);
        assert_eq!(pv.pick(&tf, &pl, [0.0, 0.0, 1.0], DOWN, f64::NAN), None);
        assert_eq!(pv.pick(&tf, &pl, [0.0, 0.0, 1.0], DOWN, 1.0), None);
        // A threshold of 0 hits where the ray enters the box (z = 0.2 m).
        let p = pv.pick(&tf, &pl, [0.0, 0.0, 1.0], DOWN, 0.0).unwrap();
        assert!((p[2] - 0.2).abs() < 1e-9, "{p:?}");
        // From inside the slab (display z 0 is volume z 20): at once.
        let p = pv.pick(&tf, &pl, [0.0, 0.0, 0.0], DOWN, 0.5).unwrap();
        assert!(p[2] <= 0.0 && p[2] > -0.1 * SCALE, "{p:?}");
        // Upwards from below the slab: its lower face, z = 12 (−0.08 m).
        let p = pv
            .pick(&tf, &pl, [0.0, 0.0, -1.0], [0.0, 0.0, 1.0], 0.5)
            .unwrap();
        assert!((p[2] + 0.08).abs() <= 0.5 * SCALE, "{p:?}");
        // A higher threshold lies deeper along the ray.
        let soft = TransferFunction::from_points(vec![
            ControlPoint::new(100.0, [1.0; 3], 0.0),
            ControlPoint::new(110.0, [1.0; 3], 0.2),
        ])
        .unwrap();
        let a = pv.pick(&soft, &pl, [0.0, 0.0, 1.0], DOWN, 0.3).unwrap();
        let b = pv.pick(&soft, &pl, [0.0, 0.0, 1.0], DOWN, 0.5).unwrap();
        assert!(b[2] < a[2], "{a:?} {b:?}");
        // τ = 0.2 per unit from z ≈ 28 down: opacity ½ after ln 2 / 0.2 ≈ 3.47
        // units.
        let want = (28.0 - 2f64.ln() / 0.2 - 20.0) * SCALE;
        // (within half a step: the step where τ ramps up is summed by the
        // trapezoid rule).
        assert!((b[2] - want).abs() <= 0.5 * SCALE, "{b:?}, want z {want}");
    }

    /// Region growing from a point: in a volume of two materials (a slab of
    /// values 190–210 with noise, an upper layer of 90–110) the band grown
    /// from inside the slab covers the slab's values and not the layer's;
    /// from the layer, the layer's; outside the box or on no data, none.
    #[test]
    fn a_band_grown_from_a_point_covers_its_material() {
        let dir = tempfile::tempdir().unwrap();
        let noisy = Volume::from_fn([N; 3], [1.0; 3], VoxelType::F32, |i, j, k| {
            let noise = (((i * 7 + j * 13 + k * 29) % 21) as f32) - 10.0;
            if (12..28).contains(&k) {
                200.0 + noise
            } else if k >= 32 {
                100.0 + noise
            } else {
                0.0
            }
        });
        let db = import(&noisy, dir.path(), "two.pxo", None);
        let pv = PickVolume::from_db(&db, PICK_VOXELS).unwrap();
        let in_slab = pv.grow_band(DVec3::new(20.0, 20.0, 20.0), 30.0).unwrap();
        let layer = pv.grow_band(DVec3::new(20.0, 20.0, 36.0), 30.0).unwrap();
        eprintln!("grown bands: in_slab {in_slab:?}, layer {layer:?}");
        for b in [in_slab, layer] {
            assert!(
                b[0] <= b[1] && b[1] <= b[2] && b[2] <= b[3] && b[0] < b[3],
                "{b:?}"
            );
        }
        assert!(
            in_slab[0] >= 185.0 && in_slab[3] <= 215.0 && in_slab[1] < 200.0 && in_slab[2] > 200.0,
            "{in_slab:?}"
        );
        assert!(layer[0] >= 85.0 && layer[3] <= 115.0, "{layer:?}");
        assert_eq!(pv.grow_band(DVec3::new(20.0, 20.0, 50.0), 30.0), None);
        assert_eq!(pv.grow_band(DVec3::new(f64::NAN, 0.0, 0.0), 30.0), None);
        // A constant region: a band about its value.
        let db = import(&slab(0.0), dir.path(), "slab.pxo", None);
        let pv = PickVolume::from_db(&db, PICK_VOXELS).unwrap();
        let b = pv.grow_band(DVec3::new(20.0, 20.0, 20.0), 4.0).unwrap();
        assert!(b[0] < 200.0 && b[3] > 200.0 && b[0] < b[3], "{b:?}");
    }
}
