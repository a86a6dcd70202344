//! Which 8×8 pixel tiles of a frame's views a ray-casting dispatch runs:
//! those whose rays can meet a leaf with data (plain kernels), or the
//! volume's box (kernels whose enhancers draw on every ray through the box).
//!
//! A pixel whose ray meets no leaf with data ends with nothing accumulated
//! (its image is zero, cleared before the dispatch), so leaving its tile out
//! changes no pixel, no feedback and no sample count. What it saves is the
//! tile's whole run: on a GPU its workgroup, on a CPU device (lavapipe) one
//! pass of the kernel's body for every SIMD row, since such a device runs
//! every branch for all lanes whether any takes it or not (docs/performance.md, "Kernel changes on a CPU device").
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
use glam::{DMat3, DVec3};
use parallax_common::camera::{Placement, View};

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

/// A box that may contribute (volume space), and the boxes within it that
/// do (for `Cull::Cells`, the rows of non-empty macrocells; empty: the box
/// itself).
struct Candidate {
    lo: DVec3,
    hi: DVec3,
    rows: std::ops::Range<usize>,
}

/// The tiles to run, each (view, tile x | tile y << 16), views in order and
/// tiles in raster order within a view. `subframe`: the views render one
/// pixel of each 2×2 quad (frame reconstruction), so a tile covers 16 × 16
/// pixels.
///
/// Per view, a leaf's rows of cells are projected only where its own box
/// covers some tile not marked yet (its rows lie inside it, so they
/// project inside its bounds); leaves are visited nearest first, so that
/// leaves behind others are mostly passed over whole. Colin27 skin at
/// 512 × 512: 3.2 → 0.55 ms a frame, the same tiles.
pub fn tiles(
    views: &[View],
    scene: &SceneGeometry,
    index: &SpatialIndex,
    cull: Cull,
    subframe: bool,
) -> Vec<[u32; 2]> {
    tiles_in(views, scene, index, cull, subframe, true)
}

/// `tiles`, passing over the leaves whose tiles are all marked (`prune`)
/// or projecting every row.
fn tiles_in(
    views: &[View],
    scene: &SceneGeometry,
    index: &SpatialIndex,
    cull: Cull,
    subframe: bool,
    prune: bool,
) -> Vec<[u32; 2]> {
    let geom = &scene.geom;
    let ext = scene.extent();
    let map = VolumeMap::new(&scene.placement, ext);
    let mut cands: Vec<Candidate> = Vec::new();
    let mut rows: Vec<(DVec3, DVec3)> = Vec::new();
    let leaves = match cull {
        Cull::Off => &[][..],
        Cull::Volume => {
            cands.push(Candidate {
                lo: DVec3::ZERO,
                hi: DVec3::from(ext),
                rows: 0..0,
            });
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
            cands.push(Candidate { lo, hi, rows: 0..0 });
            continue;
        };
        // Cell (x, y, z) spans lo + [x, x + 1]·M voxels of this level
        // along x (clamped to the box), and likewise along y and z.
        let c = cells.per_axis as usize;
        let scale = geom.layout.voxel_scale(k.level as u32);
        let side: [f64; 3] =
            std::array::from_fn(|a| (cells.voxels as usize * scale[a]) as f64 * geom.spacing[a]);
        let at = |a: usize, i: usize, base: DVec3| (base[a] + i as f64 * side[a]).min(hi[a]);
        let first = rows.len();
        for z in 0..c {
            for y in 0..c {
                let mut row = (0..c).filter(|&x| !cells.is_empty(slot, x + c * (y + c * z)));
                let (Some(x0), Some(x1)) = (row.clone().next(), row.next_back()) else {
                    continue;
                };
                let a = DVec3::new(at(0, x0, lo), at(1, y, lo), at(2, z, lo));
                let b = DVec3::new(at(0, x1 + 1, lo), at(1, y + 1, lo), at(2, z + 1, lo));
                if a.cmplt(b).all() {
                    rows.push((a, b));
                }
            }
        }
        // A leaf none of whose cells may contribute adds nothing.
        if rows.len() > first {
            cands.push(Candidate {
                lo,
                hi,
                rows: first..rows.len(),
            });
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
        // Nearest first (by the distance from the view's observer to the
        // box: only the order depends on it).
        let eye = map.to_volume(DVec3::from(v.observer));
        let mut order: Vec<(f64, usize)> = cands
            .iter()
            .enumerate()
            .map(|(i, c)| ((c.lo - eye).max(eye - c.hi).max(DVec3::ZERO).length(), i))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        // The tiles (clamped to the view) that the box's pixel bounds
        // cover, None when they cover none; Err when the whole view may
        // meet the box.
        let rect = |lo: DVec3, hi: DVec3| -> Result<Option<[u32; 4]>, ()> {
            let [c0, c1, r0, r1] = pixel_bounds(v, &map.corners(lo, hi)).ok_or(())?;
            if c1 < 0.0 || r1 < 0.0 || c0 > (w - 1) as f64 || r0 > (h - 1) as f64 {
                return Ok(None);
            }
            let tile = |p: f64, n: u32| ((p.max(0.0) as u32) / px_per_tile).min(n - 1);
            Ok(Some([
                tile(c0, tw),
                tile(c1, tw),
                tile(r0, th),
                tile(r1, th),
            ]))
        };
        let cells_of = |r: [u32; 4]| {
            (r[2]..=r[3]).flat_map(move |ty| (r[0]..=r[1]).map(move |tx| (ty * tw + tx) as usize))
        };
        // Whether some box reaches the observer's plane (or the view is
        // degenerate): then every tile.
        let whole = 'boxes: {
            for &(_, ci) in &order {
                let c = &cands[ci];
                let r = match rect(c.lo, c.hi) {
                    Err(()) => break 'boxes true,
                    Ok(None) => continue,
                    Ok(Some(r)) => r,
                };
                if c.rows.is_empty() {
                    cells_of(r).for_each(|i| mark[i] = true);
                    continue;
                }
                if prune && cells_of(r).all(|i| mark[i]) {
                    continue;
                }
                for &(lo, hi) in &rows[c.rows.clone()] {
                    match rect(lo, hi) {
                        Err(()) => break 'boxes true,
                        Ok(None) => {}
                        Ok(Some(r)) => cells_of(r).for_each(|i| mark[i] = true),
                    }
                }
            }
            false
        };
        if whole {
            mark.fill(true);
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

/// Moves the tiles (of `tiles`, made for the same views) whose rays can
/// meet one of `regions` (boxes in volume space) to the front, keeping the
/// order within each part, and returns how many they are. Those run the
/// kernel that computes what its enhancers read; the others run the same
/// kernel with all of that compiled out (`TOOL_TILES`), since a CPU device
/// runs the body of every branch for all lanes whether any takes it or not.
pub fn flag_regions(
    tiles: &mut Vec<[u32; 2]>,
    views: &[View],
    scene: &SceneGeometry,
    regions: &[[[f64; 3]; 2]],
    subframe: bool,
) -> usize {
    if regions.is_empty() {
        return 0;
    }
    let map = VolumeMap::new(&scene.placement, scene.extent());
    let px_per_tile = if subframe { 2 * TILE } else { TILE };
    // Per view, the tile rectangles [x0, x1, y0, y1] the regions cover
    // (None: every tile).
    let rects: Vec<Option<Vec<[f64; 4]>>> = views
        .iter()
        .map(|v| {
            let o = DVec3::from(v.observer);
            regions
                .iter()
                .map(|[lo, hi]| map.corners(DVec3::from(*lo), DVec3::from(*hi)))
                // A region wholly behind the rays' origins (the observer's
                // plane) meets no ray.
                .filter(|corners| !(o.z.abs() > 1e-12 && corners.iter().all(|p| p.z / o.z >= 1.0)))
                .map(|corners| {
                    let b = pixel_bounds(v, &corners)?;
                    let t = px_per_tile as f64;
                    Some([
                        (b[0] / t).floor(),
                        (b[1] / t).floor(),
                        (b[2] / t).floor(),
                        (b[3] / t).floor(),
                    ])
                })
                .collect()
        })
        .collect();
    let meets = |t: &[u32; 2]| {
        let (tx, ty) = ((t[1] & 0xFFFF) as f64, (t[1] >> 16) as f64);
        match &rects[t[0] as usize] {
            None => true,
            Some(rs) => rs
                .iter()
                .any(|r| r[0] <= tx && tx <= r[1] && r[2] <= ty && ty <= r[3]),
        }
    };
    let (mut inside, outside): (Vec<[u32; 2]>, Vec<[u32; 2]>) =
        tiles.iter().partition(|t| meets(t));
    let n = inside.len();
    inside.extend(outside);
    *tiles = inside;
    n
}

/// Volume space → display space, the placement's affine map with its
/// rotation made once (`Placement::to_display` makes it per point).
struct VolumeMap {
    /// Display point of the volume's origin, and the images of its axes
    /// (scaled).
    base: DVec3,
    axes: DMat3,
    inv_axes: DMat3,
}

impl VolumeMap {
    fn new(pl: &Placement, ext: [f64; 3]) -> Self {
        let axes = pl.rotation() * pl.scale(ext);
        let base = DVec3::from(pl.center) - axes * (DVec3::from(ext) * 0.5);
        VolumeMap {
            base,
            axes,
            inv_axes: axes.inverse(),
        }
    }

    fn to_volume(&self, x: DVec3) -> DVec3 {
        self.inv_axes * (x - self.base)
    }

    /// The display-space corners of the box [lo, hi], corner i taking hi
    /// along axis a where bit a of i is set.
    fn corners(&self, lo: DVec3, hi: DVec3) -> [DVec3; 8] {
        let p = self.base + self.axes * lo;
        let e = [
            self.axes.x_axis * (hi.x - lo.x),
            self.axes.y_axis * (hi.y - lo.y),
            self.axes.z_axis * (hi.z - lo.z),
        ];
        std::array::from_fn(|i| {
            let mut c = p;
            for (a, ea) in e.iter().enumerate() {
                if i & (1 << a) != 0 {
                    c += *ea;
                }
            }
            c
        })
    }
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

    /// A projector view of η = 1, off the observer's axis.
    fn multi_centre_view(resolution: [u32; 2]) -> View {
        View {
            resolution,
            region: [-0.15, -0.1, 0.3, 0.2],
            eye: [0.4, 0.0, 1.5],
            observer: [-0.1, 0.05, 0.9],
            eta: 1.0,
        }
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
            multi_centre_view([64, 48]),
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
    fn the_volume_map_is_the_placement() {
        let pl = Placement {
            center: [0.01, -0.02, 0.05],
            rotation_deg: [-90.0, 180.0, 30.0],
            size: 0.25,
        };
        let ext = [181.0, 217.0, 90.5];
        let map = VolumeMap::new(&pl, ext);
        let (lo, hi) = (DVec3::new(3.0, 40.0, 7.5), DVec3::new(35.0, 72.0, 39.0));
        for (i, c) in map.corners(lo, hi).iter().enumerate() {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            assert!((*c - pl.to_display(ext, p)).length() < 1e-12);
            assert!((map.to_volume(*c) - p).length() < 1e-9);
        }
    }

    /// Passing over leaves whose tiles are all marked already lists the
    /// same tiles as projecting every row of every leaf, for pinhole,
    /// multi-centre and sub-frame views.
    #[test]
    fn pruned_tiles_are_the_tiles_of_every_row() {
        use crate::index::CutNode;
        use crate::store::layout::{NodeKey, OctreeLayout};
        use std::collections::HashMap;
        let layout = OctreeLayout::new([64, 64, 64], 16);
        let mut cut = HashMap::new();
        let mut slot = 0;
        for level in 0..=2u8 {
            let n = 1u32 << level;
            for z in 0..n {
                for y in 0..n {
                    for x in 0..n {
                        let leaf = level == 2;
                        cut.insert(
                            NodeKey::new(level, x, y, z),
                            CutNode {
                                refined: !leaf,
                                slot: leaf.then(|| {
                                    slot += 1;
                                    slot - 1
                                }),
                                min: 0.0,
                                max: 1.0,
                            },
                        );
                    }
                }
            }
        }
        let index = SpatialIndex::build(&layout, &cut, (0.0, 1.0)).unwrap();
        // About 60 % of the cells empty, in a fixed pseudo-random pattern.
        let mut seed = 12345u64;
        let cells = Macrocells::with_empty(slot, 16, |_, _| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) % 10 < 6
        });
        let placement = Placement {
            center: [0.0, 0.0, 0.0],
            rotation_deg: [20.0, 35.0, 0.0],
            size: 0.1,
        };
        let scene = SceneGeometry::new(placement, layout, [1.0, 1.0, 1.0]);
        let views = [
            View::window([96, 72], [0.3, 0.22], [0.02, -0.01, 0.6]),
            multi_centre_view([80, 60]),
        ];
        for subframe in [false, true] {
            let pruned = tiles_in(&views, &scene, &index, Cull::Cells(&cells), subframe, true);
            let every = tiles_in(&views, &scene, &index, Cull::Cells(&cells), subframe, false);
            assert_eq!(pruned, every);
            let all = tiles_in(&views, &scene, &index, Cull::Off, subframe, true);
            assert!(
                !every.is_empty() && every.len() < all.len(),
                "{} of {}",
                every.len(),
                all.len()
            );
        }
    }

    #[test]
    fn a_box_around_the_observer_covers_the_view() {
        let v = View::window([64, 48], [0.3, 0.2], [0.0, 0.0, 0.5]);
        assert!(pixel_bounds(&v, &cube(DVec3::new(0.0, 0.0, 0.5), 0.1)).is_none());
        assert!(pixel_bounds(&v, &cube(DVec3::new(0.0, 0.0, 0.7), 0.1)).is_none());
    }
}
