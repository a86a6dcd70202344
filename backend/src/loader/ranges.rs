//! Value range of every subtree of the octree, for conservative empty-space
//! culling.
//!
//! An inner node's record holds the range of its own (averaged) values, which
//! can be narrower than its children's: a thin bright feature averages down.
//! Testing emptiness on it could declare a node empty while a descendant is
//! not, and the descendant would never be reached; for the same reason a node
//! dropped at import (all its averaged values below the threshold) may still
//! have stored descendants. The loader therefore culls a node as empty (G08 §4,
//! L12 §4.2) on the union of the ranges of the *stored* bricks of its
//! subtree, and on nothing when that subtree stores no brick at all.

use crate::store::{NodeKey, OctreeDb, OctreeLayout};

/// One `[min, max]` per node of the layout (8 bytes a node, about 1/1000 of
/// the data with 32³ bricks); `min > max` for a subtree with no stored brick.
#[derive(Debug)]
pub(crate) struct SubtreeRanges {
    layout: OctreeLayout,
    offsets: Vec<usize>,
    ranges: Vec<[f32; 2]>,
}

const HOLLOW: [f32; 2] = [f32::INFINITY, f32::NEG_INFINITY];

impl SubtreeRanges {
    pub fn new(db: &OctreeDb) -> Self {
        let layout = *db.layout();
        let mut offsets = Vec::with_capacity(layout.levels as usize);
        let mut total = 0;
        for l in 0..layout.levels {
            offsets.push(total);
            total += layout.level_bricks(l).iter().product::<usize>();
        }
        let mut r = SubtreeRanges {
            layout,
            offsets,
            ranges: vec![HOLLOW; total],
        };
        for rec in &db.nodes {
            if rec.is_stored() && layout.contains(rec.key) && rec.min <= rec.max {
                let i = r.index(rec.key);
                r.ranges[i] = [rec.min, rec.max];
            }
        }
        for l in (0..layout.leaf_level()).rev() {
            let n = layout.level_bricks(l);
            for z in 0..n[2] as u32 {
                for y in 0..n[1] as u32 {
                    for x in 0..n[0] as u32 {
                        let key = NodeKey::new(l as u8, x, y, z);
                        let mut acc = r.ranges[r.index(key)];
                        for c in layout.children(key) {
                            if layout.contains(c) {
                                let cr = r.ranges[r.index(c)];
                                acc = [acc[0].min(cr[0]), acc[1].max(cr[1])];
                            }
                        }
                        let i = r.index(key);
                        r.ranges[i] = acc;
                    }
                }
            }
        }
        r
    }

    fn index(&self, key: NodeKey) -> usize {
        let n = self.layout.level_bricks(key.level as u32);
        self.offsets[key.level as usize]
            + (key.z as usize * n[1] + key.y as usize) * n[0]
            + key.x as usize
    }

    /// The range of the stored bricks of the subtree under `key`; `None` when
    /// it stores none (or the node is outside the octree).
    pub fn get(&self, key: NodeKey) -> Option<(f32, f32)> {
        if !self.layout.contains(key) {
            return None;
        }
        let [lo, hi] = self.ranges[self.index(key)];
        (lo <= hi).then_some((lo, hi))
    }
}
