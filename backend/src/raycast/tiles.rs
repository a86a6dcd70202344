//! Which 8×8 pixel tiles of a frame's views a ray-casting dispatch runs:
//! those whose rays can meet a leaf with data (plain kernels), or the
//! volume's box (kernels whose enhancers draw on every ray through the box).
//!
//! A pixel whose ray meets no leaf with data ends with nothing accumulated
//! (its image is zero, cleared before the dispatch), so leaving its tile out
//! changes no pixel, no feedback and no sample count. What it saves is the
//! tile's whole run: on a GPU its workgroup, on a CPU device (lavapipe) one
//! pass of the kernel's body for every SIMD row, since such a device runs
//! every branch for all lanes whether any takes it or not (docs/figures.md).
//! On the Colin27 views of `bench/vtk_compare.sh` over half the tiles of
//! the 512 × 512 image have no pixel with any opacity.
//!
//! The projection is exact for G10's multi-centre rays (Eq. 1): for a point
//! P at depth P_z, the ray through screen point Q that reaches it leaves its
//! origin (on the plane z = V_z) at s = 1 − P_z / V_z of the way to the
//! screen, so Q_y = (P_y − V_y(1 − s)) / s and, the origin's x being affine
//! in Q_x (O_x = a + b·Q_x), Q_x = (P_x − a(1 − s)) / (b(1 − s) + s). Each is
//! linear-fractional in P with a denominator of one sign over a box where it
//! is positive at the corners, so its extremes over the box lie at corners:
//! the corners' screen bounds hold every ray that meets the box. A box that
//! reaches the observer's plane (or a degenerate view) covers the whole view.

use crate::index::SpatialIndex;
use crate::loader::geometry::Geometry;
use glam::DVec3;
use parallax_common::camera::View;

use super::pool::Macrocells;
use super::SceneGeometry;

/// Pixels per tile side: the kernel's workgroup is one tile.
pub const TILE: u32 = 8;

/// Workgroups along x of a tile dispatch (the rest go along y): below
/// every device's per-dimension limit of 65535.
pub const TILES_PER_ROW: u32 = 32768;

/// Pixels of margin around a projected box (the kernel's rays are computed
/// in f32).
const MARGIN_PX: f64 = 1.0;

/// What may contribute to a pixel.
#[derive(Clone, Copy)]
pub enum Cull<'a> {
    /// Nothing: every tile of every view.
    Off,
    /// The volume's box: every ray through it.
    Volume,
    /// The leaves with data.
    Leaves,
    /// Their macrocells not empty under the transfer function (as marked
    /// for the kernel's empty-space skipping): per leaf, each row of cells
    /// along x from its first non-empty cell to its last.
    Cells(&'a Macrocells),
}

/// The tiles to run, each (view, tile x | tile y << 16), views in order and
/// tiles in raster order within a view. `subframe`: the views render one
/// pixel of each 2×2 quad (frame reconstruction), so a tile covers 16 × 16
/// pixels.
pub fn tiles(
    views: &[View],
    scene: &SceneGeometry,
    index: &SpatialIndex,
    cull: Cull,
    subframe: bool,
) -> Vec<[u32; 2]> {
    let geom = Geometry::new(scene.layout, scene.spacing);
    let pl = &scene.placement;
    let ext = scene.extent();
    // Display-space corners of every box that may contribute.
    let mut boxes: Vec<[DVec3; 8]> = Vec::new();
    let mut add = |lo: DVec3, hi: DVec3| {
        boxes.push(std::array::from_fn(|i| {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            pl.to_display(ext, p)
        }));
    };
    let leaves = match cull {
        Cull::Off => &[][..],
        Cull::Volume => {
            add(DVec3::ZERO, DVec3::from(ext));
            &[][..]
        }
        Cull::Leaves | Cull::Cells(_) => &index.nodes[..],
    };
    for (n, k) in leaves.iter().zip(&index.keys) {
        let Some(slot) = n.slot().filter(|_| n.first_child().is_none()) else {
            continue;
        };
        let (lo, hi) = geom.node_box(*k);
        let Cull::Cells(cells) = cull else {
            add(lo, hi);
            continue;
        };
        // Cell (x, y, z) spans lo + [x, x + 1]·M voxels of this level
        // along x (clamped to the box), and likewise along y and z.
        let c = cells.per_axis as usize;
        let scale = scene.layout.voxel_scale(k.level as u32);
        let side: [f64; 3] =
            std::array::from_fn(|a| (cells.voxels as usize * scale[a]) as f64 * scene.spacing[a]);
        let at = |a: usize, i: usize, base: DVec3| (base[a] + i as f64 * side[a]).min(hi[a]);
        for z in 0..c {
            for y in 0..c {
                let mut row = (0..c).filter(|&x| !cells.is_empty(slot, x + c * (y + c * z)));
                let (Some(x0), Some(x1)) = (row.clone().next(), row.next_back()) else {
                    continue;
                };
                let a = DVec3::new(at(0, x0, lo), at(1, y, lo), at(2, z, lo));
                let b = DVec3::new(at(0, x1 + 1, lo), at(1, y + 1, lo), at(2, z + 1, lo));
                if a.cmplt(b).all() {
                    add(a, b);
                }
            }
        }
    }
    let px_per_tile = if subframe { 2 * TILE } else { TILE };
    let mut out = Vec::new();
    for (vi, v) in views.iter().enumerate() {
        let [w, h] = v.resolution;
        let tw = w.div_ceil(px_per_tile);
        let th = h.div_ceil(px_per_tile);
        if tw == 0 || th == 0 {
            continue;
        }
        let mut mark = vec![matches!(cull, Cull::Off); (tw * th) as usize];
        for corners in &boxes {
            let Some([c0, c1, r0, r1]) = pixel_bounds(v, corners) else {
                mark.fill(true);
                break;
            };
            // Pixel columns c0..=c1, rows r0..=r1 (clamped to the view).
            if c1 < 0.0 || r1 < 0.0 || c0 > (w - 1) as f64 || r0 > (h - 1) as f64 {
                continue;
            }
            let tile = |p: f64, n: u32| ((p.max(0.0) as u32) / px_per_tile).min(n - 1);
            for ty in tile(r0, th)..=tile(r1, th) {
                for tx in tile(c0, tw)..=tile(c1, tw) {
                    mark[(ty * tw + tx) as usize] = true;
                }
            }
        }
        for ty in 0..th {
            for tx in 0..tw {
                if mark[(ty * tw + tx) as usize] {
                    out.push([vi as u32, tx | ty << 16]);
                }
            }
        }
    }
    out
}

/// The columns and rows [c0, c1] × [r0, r1] (pixel indices, possibly
/// outside the view) whose rays can meet the convex hull of `corners`
/// (display space), or `None` when the whole view may.
fn pixel_bounds(v: &View, corners: &[DVec3; 8]) -> Option<[f64; 4]> {
    let e = DVec3::from(v.eye);
    let o = DVec3::from(v.observer);
    let [x0, y0, rw, rh] = v.region;
    let [w, h] = v.resolution;
    if o.z.abs() < 1e-12 || rw.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || rh <= 0.0 {
        return None;
    }
    // The ray origin's x as a + b·Q_x (View::ray).
    let (a, b) = if e.z.abs() > 1e-12 {
        let k = 1.0 - o.z / e.z;
        ((1.0 - v.eta) * o.x + v.eta * e.x * (1.0 - k), v.eta * k)
    } else {
        (o.x, 0.0)
    };
    let (mut qx0, mut qx1, mut qy0, mut qy1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in corners {
        let s = 1.0 - p.z / o.z;
        let den = b * (1.0 - s) + s;
        if !(s > 1e-9 && den > 1e-9) {
            return None;
        }
        let qx = (p.x - a * (1.0 - s)) / den;
        let qy = (p.y - o.y * (1.0 - s)) / s;
        if !(qx.is_finite() && qy.is_finite()) {
            return None;
        }
        qx0 = qx0.min(qx);
        qx1 = qx1.max(qx);
        qy0 = qy0.min(qy);
        qy1 = qy1.max(qy);
    }
    // Pixel i's ray passes through x0 + (i + ½)/W·rw; row j's through
    // y0 + rh − (j + ½)/H·rh.
    let col = |q: f64| (q - x0) / rw * w as f64 - 0.5;
    let row = |q: f64| (y0 + rh - q) / rh * h as f64 - 0.5;
    Some([
        (col(qx0) - MARGIN_PX).ceil(),
        (col(qx1) + MARGIN_PX).floor(),
        (row(qy1) - MARGIN_PX).ceil(),
        (row(qy0) + MARGIN_PX).floor(),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray_meets(v: &View, i: u32, j: u32, corners: &[DVec3; 8]) -> bool {
        // The box is axis-aligned in these tests: slab test in display space.
        let (o, d) = v.ray(i, j);
        let lo = corners.iter().fold(DVec3::MAX, |m, c| m.min(*c));
        let hi = corners.iter().fold(DVec3::MIN, |m, c| m.max(*c));
        let inv = d.recip();
        let t0 = (lo - o) * inv;
        let t1 = (hi - o) * inv;
        let tn = t0.min(t1).max_element().max(0.0);
        let tf = t0.max(t1).min_element();
        tn <= tf
    }

    fn cube(c: DVec3, r: f64) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            c + DVec3::new(
                if i & 1 == 0 { -r } else { r },
                if i & 2 == 0 { -r } else { r },
                if i & 4 == 0 { -r } else { r },
            )
        })
    }

    /// Every pixel whose ray meets the box lies within the bounds, for
    /// pinhole and multi-centre views, and the bounds are tight to the
    /// margin.
    #[test]
    fn bounds_hold_every_ray_that_meets_the_box() {
        let views = [
            View::window([64, 48], [0.3, 0.2], [0.02, -0.01, 0.8]),
            View {
                resolution: [64, 48],
                region: [-0.15, -0.1, 0.3, 0.2],
                eye: [0.4, 0.0, 1.5],
                observer: [-0.1, 0.05, 0.9],
                eta: 1.0,
            },
            View {
                resolution: [64, 48],
                region: [-0.15, -0.1, 0.3, 0.2],
                eye: [-0.3, 0.0, 1.2],
                observer: [0.0, 0.0, 0.7],
                eta: 0.5,
            },
        ];
        for v in &views {
            for (c, r) in [
                (DVec3::new(0.0, 0.0, 0.0), 0.03),
                (DVec3::new(0.05, -0.04, 0.1), 0.02),
                (DVec3::new(-0.08, 0.03, -0.2), 0.05),
            ] {
                let corners = cube(c, r);
                let [c0, c1, r0, r1] = pixel_bounds(v, &corners).expect("in front");
                let mut hits = 0;
                for j in 0..v.resolution[1] {
                    for i in 0..v.resolution[0] {
                        if ray_meets(v, i, j, &corners) {
                            hits += 1;
                            let (i, j) = (i as f64, j as f64);
                            assert!(
                                i >= c0 && i <= c1 && j >= r0 && j <= r1,
                                "{v:?} {c} ({i}, {j})"
                            );
                        }
                    }
                }
                assert!(hits > 0);
                // Tight: the bounds' area is not much more than the hit
                // pixels' bounding rectangle with the margin.
                assert!((c1 - c0 + 1.0) * (r1 - r0 + 1.0) <= 2.0 * hits as f64 + 200.0);
            }
        }
    }

    #[test]
    fn a_box_around_the_observer_covers_the_view() {
        let v = View::window([64, 48], [0.3, 0.2], [0.0, 0.0, 0.5]);
        assert!(pixel_bounds(&v, &cube(DVec3::new(0.0, 0.0, 0.5), 0.1)).is_none());
        assert!(pixel_bounds(&v, &cube(DVec3::new(0.0, 0.0, 0.7), 0.1)).is_none());
    }
}
