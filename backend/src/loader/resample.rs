//! A registered layer on another grid (`[[layer]] transform`): its own
//! octree, read through its own index (its database's nodes and subtree
//! ranges) and resampled onto the scene volume's bricks as they are read,
//! so that the kernel's one traversal of the volume's octree serves it as
//! it serves a layer on the volume's grid (shaders/shared/layers.wgsl).
//!
//! A brick of the volume's node at level l is filled, voxel by voxel, with
//! the layer's value at that voxel's centre: mapped into the layer's space
//! by the inverse of the layer's transform, and interpolated trilinearly
//! (a label layer: read at the nearest voxel, so labels stay whole) in the
//! layer's level whose voxels are no larger than the node's smallest voxel
//! edge (so a layer keeps at least the volume's detail at every level).
//! Only the layer's bricks that the node's voxels reach are read, and of
//! those only the ones its transfer function sees; outside the layer's box
//! there is no medium ([`NO_LAYER`]).

use super::cache::ByteLru;
use super::ranges::SubtreeRanges;
use crate::store::{Brick, NodeKey, OctreeDb, OctreeLayout, OVERLAP};
use anyhow::Result;
use parallax_common::tf::EmptinessTable;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// An affine map x ↦ m·x + t (rows of `m`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Affine {
    pub m: [[f64; 3]; 3],
    pub t: [f64; 3],
}

impl Affine {
    /// The map of three rows `[a, b, c, t]` (a `transform`, a database's
    /// scanner geometry).
    pub fn from_rows(w: &[[f64; 4]; 3]) -> Affine {
        Affine {
            m: std::array::from_fn(|r| [w[r][0], w[r][1], w[r][2]]),
            t: [w[0][3], w[1][3], w[2][3]],
        }
    }

    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|r| {
            self.m[r][0] * p[0] + self.m[r][1] * p[1] + self.m[r][2] * p[2] + self.t[r]
        })
    }

    /// The map `self ∘ first` (first `first`, then `self`).
    pub fn compose(&self, first: &Affine) -> Affine {
        let m = std::array::from_fn(|r| {
            std::array::from_fn(|c| (0..3).map(|k| self.m[r][k] * first.m[k][c]).sum())
        });
        Affine {
            m,
            t: self.apply(first.t),
        }
    }

    /// The inverse map; `None` where the linear part is singular.
    pub fn inverse(&self) -> Option<Affine> {
        let m = &self.m;
        let cof = |r0: usize, r1: usize, c0: usize, c1: usize| {
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let det = m[0][0] * cof(1, 2, 1, 2) - m[0][1] * cof(1, 2, 0, 2) + m[0][2] * cof(1, 2, 0, 1);
        let scale = m.as_flattened().iter().fold(0.0f64, |a, x| a.max(x.abs()));
        if !det.is_finite() || det.abs() <= 1e-12 * scale.powi(3) {
            return None;
        }
        let inv = [
            [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
            [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
            [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
        ]
        .map(|row| row.map(|x| x / det));
        let t = std::array::from_fn(|r| {
            -(inv[r][0] * self.t[0] + inv[r][1] * self.t[1] + inv[r][2] * self.t[2])
        });
        Some(Affine { m: inv, t })
    }

    /// The length of the image of axis `k`'s unit vector.
    fn column_norm(&self, k: usize) -> f64 {
        (0..3)
            .map(|r| self.m[r][k] * self.m[r][k])
            .sum::<f64>()
            .sqrt()
    }

    /// The bounding box of the image of the box [lo, hi].
    pub fn map_box(&self, lo: [f64; 3], hi: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        let mut a = [f64::INFINITY; 3];
        let mut b = [f64::NEG_INFINITY; 3];
        for c in 0..8 {
            let p = std::array::from_fn(|k| if c & (1 << k) != 0 { hi[k] } else { lo[k] });
            let q = self.apply(p);
            for k in 0..3 {
                a[k] = a[k].min(q[k]);
                b[k] = b[k].max(q[k]);
            }
        }
        (a, b)
    }
}

/// What a volume node sees of the layer: whether every layer brick it
/// reaches is empty under the layer's function (subtrees included), and
/// whether one of them has data to read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Cover {
    pub culled: bool,
    pub needs_data: bool,
}

/// A placed layer's value where it has no data (outside its box, or a
/// brick it does not store): no medium at all in the kernel
/// (shaders/shared/layers.wgsl `NO_LAYER_BELOW`), never interpolated into
/// a value.
pub(crate) const NO_LAYER: f32 = -3.0e38;

/// The layer level voxels a volume node's samples read: level, first and
/// last voxel per axis (inclusive).
type Region = (u32, [i64; 3], [i64; 3]);

/// A layer placed in the scene volume by an affine map.
pub(crate) struct Placed {
    db: Arc<OctreeDb>,
    ranges: SubtreeRanges,
    /// The scene volume's octree and spacing.
    vol: OctreeLayout,
    vol_spacing: [f64; 3],
    /// Scene volume space → the layer's (data units).
    to_layer: Affine,
    /// Labels: the nearest voxel, never an interpolation.
    nearest: bool,
    /// Per volume level, the layer level its bricks are resampled from.
    level_of: Vec<u32>,
    covers: Mutex<HashMap<NodeKey, Cover>>,
    /// The layer's decoded bricks read last (a layer brick serves the
    /// several volume nodes it overlaps, which the loader asks for close
    /// together); its bytes are taken from the loader's CPU budget.
    recent: Mutex<ByteLru>,
}

/// The share of the CPU cache budget a placed layer's own cache of decoded
/// bricks takes (`Placed::recent`), and its most.
pub(crate) const RECENT_SHARE: u64 = 16;
pub(crate) const RECENT_MOST: u64 = 64 << 20;

impl Placed {
    /// The layer `db` placed by `to_volume` (layer space → the volume's)
    /// in the scene volume of `vol` voxels of `vol_spacing`; `None` where
    /// the map is singular.
    pub fn new(
        db: Arc<OctreeDb>,
        vol: OctreeLayout,
        vol_spacing: [f64; 3],
        to_volume: Affine,
        nearest: bool,
        recent_bytes: u64,
    ) -> Option<Self> {
        let to_layer = to_volume.inverse()?;
        let lay = *db.layout();
        let lsp = db.header.info.spacing;
        // The layer's voxel edges at level k, measured in the volume.
        let edge = |k: u32| {
            let s = lay.voxel_scale(k);
            (0..3)
                .map(|a| to_volume.column_norm(a) * lsp[a] * s[a] as f64)
                .fold(0.0f64, f64::max)
        };
        let level_of = (0..vol.levels)
            .map(|l| {
                let s = vol.voxel_scale(l);
                let finest = (0..3)
                    .map(|a| vol_spacing[a] * s[a] as f64)
                    .fold(f64::INFINITY, f64::min);
                (0..lay.levels)
                    .find(|&k| edge(k) <= finest * (1.0 + 1e-6))
                    .unwrap_or(lay.levels - 1)
            })
            .collect();
        Some(Placed {
            ranges: SubtreeRanges::new(&db),
            db,
            vol,
            vol_spacing,
            to_layer,
            nearest,
            level_of,
            covers: Mutex::new(HashMap::new()),
            recent: Mutex::new(ByteLru::new(recent_bytes)),
        })
    }

    /// A new budget for the layer's own cache of decoded bricks.
    pub fn set_recent_budget(&self, bytes: u64) {
        self.recent.lock().unwrap().set_budget(bytes);
    }

    /// The volume's level-`l` voxel size (data units).
    fn vol_voxel(&self, l: u32) -> [f64; 3] {
        let s = self.vol.voxel_scale(l);
        std::array::from_fn(|a| self.vol_spacing[a] * s[a] as f64)
    }

    /// The layer's level-`k` voxel size.
    fn layer_voxel(&self, k: u32) -> [f64; 3] {
        let s = self.db.layout().voxel_scale(k);
        let sp = self.db.header.info.spacing;
        std::array::from_fn(|a| sp[a] * s[a] as f64)
    }

    /// The volume node's stored voxels along each axis: first and last
    /// level voxel index (clamped to the level's grid, as the stored
    /// bricks' overlap is).
    fn node_voxels(&self, key: NodeKey) -> ([i64; 3], [i64; 3]) {
        let b = self.vol.brick as i64;
        let d = self.vol.level_dims(key.level as u32);
        let c = key.coords();
        let lo =
            std::array::from_fn(|a| (c[a] as i64 * b - OVERLAP as i64).clamp(0, d[a] as i64 - 1));
        let hi = std::array::from_fn(|a| {
            (c[a] as i64 * b + b + OVERLAP as i64 - 1).clamp(0, d[a] as i64 - 1)
        });
        (lo, hi)
    }

    /// The layer level voxels `key`'s samples read (`None`: its box misses
    /// the layer's).
    fn region(&self, key: NodeKey) -> Option<Region> {
        let l = key.level as u32;
        let k = self.level_of[l as usize];
        let vv = self.vol_voxel(l);
        let (jlo, jhi) = self.node_voxels(key);
        let plo = std::array::from_fn(|a| (jlo[a] as f64 + 0.5) * vv[a]);
        let phi = std::array::from_fn(|a| (jhi[a] as f64 + 0.5) * vv[a]);
        let (qlo, qhi) = self.to_layer.map_box(plo, phi);
        let lay = self.db.layout();
        let ext = crate::volume::extent(lay.dims, self.db.header.info.spacing);
        if (0..3).any(|a| qhi[a] < 0.0 || qlo[a] > ext[a]) {
            return None;
        }
        let lv = self.layer_voxel(k);
        let ld = lay.level_dims(k);
        let lo = std::array::from_fn(|a| {
            ((qlo[a] / lv[a] - 0.5).floor() as i64).clamp(0, ld[a] as i64 - 1)
        });
        let hi = std::array::from_fn(|a| {
            ((qhi[a] / lv[a] - 0.5).floor() as i64 + 1).clamp(0, ld[a] as i64 - 1)
        });
        Some((k, lo, hi))
    }

    /// The layer's bricks at the region's level that hold its voxels.
    fn bricks(&self, (k, lo, hi): Region) -> impl Iterator<Item = NodeKey> {
        let b = self.db.layout().brick as i64;
        let (blo, bhi): ([i64; 3], [i64; 3]) = (lo.map(|v| v / b), hi.map(|v| v / b));
        (blo[2]..=bhi[2]).flat_map(move |z| {
            (blo[1]..=bhi[1]).flat_map(move |y| {
                (blo[0]..=bhi[0]).map(move |x| NodeKey::new(k as u8, x as u32, y as u32, z as u32))
            })
        })
    }

    /// What the volume node `key` sees of the layer under `empty` (fixed for
    /// the loader's life: remembered per node).
    pub fn cover(&self, key: NodeKey, empty: &EmptinessTable) -> Cover {
        if let Some(c) = self
            .covers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return *c;
        }
        let mut c = Cover {
            culled: true,
            needs_data: false,
        };
        if key.level as usize >= self.level_of.len() {
            return c;
        }
        if let Some(r) = self.region(key) {
            for bk in self.bricks(r) {
                if self
                    .ranges
                    .get(bk)
                    .is_some_and(|(lo, hi)| !empty.is_empty(lo as f64, hi as f64))
                {
                    c.culled = false;
                }
                if self
                    .db
                    .node(bk)
                    .is_some_and(|n| n.is_stored() && !empty.is_empty(n.min as f64, n.max as f64))
                {
                    c.needs_data = true;
                }
            }
        }
        self.covers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, c);
        c
    }

    /// The layer resampled onto the volume node `key`'s stored voxels (the
    /// volume's brick layout; [`NO_LAYER`] where the layer has no data),
    /// and the bytes read; `None` where it reads no brick of the layer.
    pub fn brick(&self, key: NodeKey, empty: &EmptinessTable) -> Result<(Option<Vec<f32>>, u64)> {
        let Some(region @ (k, lo, hi)) = self.region(key) else {
            return Ok((None, 0));
        };
        // The region's voxels, gathered from the bricks that hold them: a
        // brick the layer's function sees is read, one it leaves empty
        // takes its smallest value (it draws nothing either way), one not
        // stored has no data.
        let n: [usize; 3] = std::array::from_fn(|a| (hi[a] - lo[a] + 1) as usize);
        let mut dense = vec![f32::NAN; n[0] * n[1] * n[2]];
        let lay = *self.db.layout();
        let (b, side) = (lay.brick as i64, lay.stored_side() as i64);
        let mut bytes = 0u64;
        let mut read_any = false;
        for bk in self.bricks(region) {
            let Some(rec) = self.db.node(bk).filter(|r| r.is_stored()) else {
                continue;
            };
            let values = if empty.is_empty(rec.min as f64, rec.max as f64) {
                None
            } else {
                read_any = true;
                let cached = self
                    .recent
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .get(bk);
                match cached {
                    Some(b) => Some(b),
                    None => {
                        bytes += rec.len as u64;
                        let read = self.db.read_brick(bk)?.map(|values| {
                            Arc::new(Brick {
                                values,
                                cells: None,
                                layered: None,
                            })
                        });
                        if let Some(b) = &read {
                            self.recent
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .insert(bk, b.clone());
                        }
                        read
                    }
                }
            };
            let c = bk.coords().map(|v| v as i64 * b);
            let from: [i64; 3] = std::array::from_fn(|a| c[a].max(lo[a]));
            let to: [i64; 3] = std::array::from_fn(|a| (c[a] + b - 1).min(hi[a]));
            for z in from[2]..=to[2] {
                for y in from[1]..=to[1] {
                    for x in from[0]..=to[0] {
                        let d = ((z - lo[2]) as usize * n[1] + (y - lo[1]) as usize) * n[0]
                            + (x - lo[0]) as usize;
                        dense[d] = match &values {
                            Some(v) => {
                                let s = |g: i64, a: usize| g - c[a] + OVERLAP as i64;
                                v.values[((s(z, 2) * side + s(y, 1)) * side + s(x, 0)) as usize]
                            }
                            None => rec.min,
                        };
                    }
                }
            }
        }
        if !read_any {
            return Ok((None, bytes));
        }
        let at = |g: [i64; 3]| {
            dense[((g[2] - lo[2]) as usize * n[1] + (g[1] - lo[1]) as usize) * n[0]
                + (g[0] - lo[0]) as usize]
        };
        let lv = self.layer_voxel(k);
        let ext = crate::volume::extent(lay.dims, self.db.header.info.spacing);
        let vv = self.vol_voxel(key.level as u32);
        let vside = self.vol.stored_side();
        let vb = self.vol.brick as i64;
        let vd = self.vol.level_dims(key.level as u32);
        let kc = key.coords();
        let mut out = vec![NO_LAYER; vside * vside * vside];
        for (i, o) in out.iter_mut().enumerate() {
            let t = [i % vside, (i / vside) % vside, i / (vside * vside)];
            let p: [f64; 3] = std::array::from_fn(|a| {
                let j =
                    (kc[a] as i64 * vb - OVERLAP as i64 + t[a] as i64).clamp(0, vd[a] as i64 - 1);
                (j as f64 + 0.5) * vv[a]
            });
            let q = self.to_layer.apply(p);
            if (0..3).any(|a| !(q[a] >= 0.0 && q[a] <= ext[a])) {
                continue;
            }
            let g: [f64; 3] =
                std::array::from_fn(|a| (q[a] / lv[a] - 0.5).clamp(lo[a] as f64, hi[a] as f64));
            if self.nearest {
                let v = at(g.map(|x| x.round() as i64));
                *o = if v.is_nan() { NO_LAYER } else { v };
                continue;
            }
            // Trilinear over the taps that have data (as the kernel's
            // no-data sampling does).
            let f: [i64; 3] = g.map(|x| x.floor() as i64);
            let w: [f64; 3] = std::array::from_fn(|a| g[a] - f[a] as f64);
            let (mut sum, mut wsum) = (0.0f64, 0.0f64);
            for c in 0..8 {
                let mut tap = f;
                let mut wt = 1.0;
                for a in 0..3 {
                    if c & (1 << a) != 0 {
                        tap[a] = (f[a] + 1).min(hi[a]);
                        wt *= w[a];
                    } else {
                        wt *= 1.0 - w[a];
                    }
                }
                if wt == 0.0 {
                    continue;
                }
                let v = at(tap);
                if !v.is_nan() {
                    sum += wt * v as f64;
                    wsum += wt;
                }
            }
            if wsum > 0.0 {
                *o = (sum / wsum) as f32;
            }
        }
        Ok((Some(out), bytes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_affine_and_its_inverse_undo_each_other() {
        let a = Affine {
            m: [[0.0, -2.0, 0.0], [1.0, 0.0, 0.5], [0.0, 0.0, 3.0]],
            t: [4.0, -1.0, 2.5],
        };
        let inv = a.inverse().unwrap();
        for p in [[0.0, 0.0, 0.0], [1.5, -2.0, 7.25], [100.0, 3.0, -4.0]] {
            let q = inv.apply(a.apply(p));
            assert!((0..3).all(|k| (q[k] - p[k]).abs() < 1e-12), "{p:?} → {q:?}");
        }
        let flat = Affine {
            m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
            t: [0.0; 3],
        };
        assert!(flat.inverse().is_none());
        let both = inv.compose(&a);
        for p in [[2.0, -3.0, 0.5], [0.0, 9.0, 1.0]] {
            let q = both.apply(p);
            assert!((0..3).all(|k| (q[k] - p[k]).abs() < 1e-12), "{p:?} → {q:?}");
        }
        let (lo, hi) = a.map_box([0.0; 3], [1.0; 3]);
        assert_eq!(lo, [2.0, -1.0, 2.5]);
        assert_eq!(hi, [4.0, 0.5, 5.5]);
    }
}
