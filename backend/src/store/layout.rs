//! Geometry of the octree: how many levels, the voxel grid of each level and
//! the bricks that tile it.

use serde::{Deserialize, Serialize};

/// Voxels replicated from the neighbours on every side of a brick: one layer
/// for trilinear interpolation plus one for central differences (G08 §3,
/// G10 §5 "2 voxels overlap in every direction").
pub const OVERLAP: usize = 2;

/// Which node: level (0 = root) and brick coordinates within that level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct NodeKey {
    pub level: u8,
    pub z: u32,
    pub y: u32,
    pub x: u32,
}

impl NodeKey {
    pub fn new(level: u8, x: u32, y: u32, z: u32) -> Self {
        NodeKey { level, z, y, x }
    }

    pub fn root() -> Self {
        NodeKey::new(0, 0, 0, 0)
    }

    pub fn coords(self) -> [u32; 3] {
        [self.x, self.y, self.z]
    }
}

impl std::fmt::Display for NodeKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "level {} ({}, {}, {})",
            self.level, self.x, self.y, self.z
        )
    }
}

/// The shape of an octree over a volume of `dims` voxels with bricks of
/// `brick`³ voxels.
///
/// Each level above the source halves some of the three axes: all of them
/// in an isotropic octree, or, over thick slices, only those finer than the
/// others until the voxels are near-cubic (as multiscale formats such as
/// OME-Zarr and neuroglancer's precomputed volumes do). A node therefore
/// has 2, 4 or 8 children: two along every axis its children's level
/// halves. `splits[a]` has bit l set when level l has twice as many voxels
/// along axis a as level l − 1 (bit 0 is never set).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OctreeLayout {
    pub dims: [usize; 3],
    pub brick: usize,
    /// Number of levels, L + 1 (the root is level 0, the source level L).
    pub levels: u32,
    /// Per axis, the levels that halve it (bit l: level l against l − 1).
    pub splits: [u32; 3],
}

/// Most levels an octree may have (the split masks are 32-bit words).
pub const MAX_LEVELS: u32 = 32;

/// The split mask of an axis that every level below the root halves (bits
/// 1 … levels − 1); 0 for a level count out of range.
pub fn every_level_splits(levels: u32) -> u32 {
    if (1..=MAX_LEVELS).contains(&levels) {
        ((1u64 << levels) - 2) as u32
    } else {
        0
    }
}

/// An axis whose voxels are at most this much longer than the shortest
/// voxel edge is halved with it (√2: voxels stay within a factor √2 of
/// cubic once the finer axes have caught up).
const NEAR_CUBIC: f64 = std::f64::consts::SQRT_2;

impl OctreeLayout {
    /// The smallest isotropic octree whose root, B·2^L voxels wide, covers
    /// the volume: every level halves all three axes.
    pub fn new(dims: [usize; 3], brick: usize) -> Self {
        assert!(brick >= 1 && dims.iter().all(|&d| d >= 1));
        let largest = *dims.iter().max().unwrap();
        let mut depth = 0u32;
        while (brick << depth) < largest {
            depth += 1;
        }
        OctreeLayout {
            dims,
            brick,
            levels: depth + 1,
            splits: [every_level_splits(depth + 1); 3],
        }
    }

    /// The octree for voxels of `spacing`: going up from the source, each
    /// level halves the axes whose voxel edge is within √2 of the shortest
    /// (so on 0.5 × 0.5 × 4 mm slices the levels above the source have
    /// 1 × 1 × 4, 2 × 2 × 4, then 4 × 4 × 4 and 8 × 8 × 8 mm voxels), until
    /// one brick covers the volume. Near-cubic voxels give the isotropic
    /// octree of [`OctreeLayout::new`].
    pub fn for_spacing(dims: [usize; 3], brick: usize, spacing: [f64; 3]) -> Self {
        assert!(brick >= 1 && dims.iter().all(|&d| d >= 1));
        let iso = Self::new(dims, brick);
        if !spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
            return iso;
        }
        // Halvings from the source up: which axes each one halves.
        let mut steps: Vec<[bool; 3]> = Vec::new();
        let mut edge = spacing;
        let mut cover = [brick; 3];
        // Voxels along each axis at the level being built: an axis down to
        // one voxel no longer sets the pace (a fine axis of a thin volume
        // would otherwise be halved alone, level after level).
        let mut n = dims;
        while (0..3).any(|a| cover[a] < dims[a]) {
            let shortest = (0..3)
                .filter(|&a| n[a] > 1)
                .map(|a| edge[a])
                .fold(f64::INFINITY, f64::min);
            let halve: [bool; 3] = std::array::from_fn(|a| edge[a] <= shortest * NEAR_CUBIC);
            for a in 0..3 {
                if halve[a] {
                    edge[a] *= 2.0;
                    cover[a] = cover[a].saturating_mul(2);
                    n[a] = n[a].div_ceil(2);
                }
            }
            steps.push(halve);
            if steps.len() as u32 >= MAX_LEVELS - 1 {
                return iso;
            }
        }
        let levels = steps.len() as u32 + 1;
        let mut splits = [0u32; 3];
        // The first halving above the source is what the source level has
        // against level L − 1.
        for (i, halve) in steps.iter().enumerate() {
            let level = levels - 1 - i as u32;
            for a in 0..3 {
                if halve[a] {
                    splits[a] |= 1 << level;
                }
            }
        }
        OctreeLayout {
            dims,
            brick,
            levels,
            splits,
        }
    }

    /// L: the level that holds the source voxels.
    pub fn leaf_level(&self) -> u32 {
        self.levels - 1
    }

    /// Which axes level `level` halves against level − 1 (none at the root).
    pub fn split(&self, level: u32) -> [bool; 3] {
        self.splits.map(|m| level < 32 && (m >> level) & 1 == 1)
    }

    /// Halvings of each axis from the root down to `level`.
    fn halvings(&self, level: u32) -> [u32; 3] {
        let upto = if level >= 31 {
            u32::MAX
        } else {
            (2u32 << level) - 1
        };
        self.splits.map(|m| (m & upto).count_ones())
    }

    /// Nodes along each axis of the root's domain at `level` (2^halvings;
    /// some lie outside the volume).
    pub fn level_cells(&self, level: u32) -> [u64; 3] {
        self.halvings(level).map(|h| 1u64 << h)
    }

    /// Source voxels per level-`level` voxel along each axis: 2^(halvings
    /// below the level).
    pub fn voxel_scale(&self, level: u32) -> [usize; 3] {
        let all = self.halvings(self.leaf_level());
        let here = self.halvings(level);
        std::array::from_fn(|a| 1usize << (all[a] - here[a]))
    }

    /// The root's box in source voxels along each axis: B · voxel_scale(0).
    pub fn root_voxels(&self) -> [usize; 3] {
        self.voxel_scale(0).map(|s| s * self.brick)
    }

    /// Voxel grid of a level: ⌈dims / scale⌉ (each halving rounds up, so a
    /// coarse voxel at an odd edge averages fewer fine voxels).
    pub fn level_dims(&self, level: u32) -> [usize; 3] {
        let s = self.voxel_scale(level);
        std::array::from_fn(|a| self.dims[a].div_ceil(s[a]))
    }

    /// Bricks per axis at a level.
    pub fn level_bricks(&self, level: u32) -> [usize; 3] {
        self.level_dims(level).map(|d| d.div_ceil(self.brick))
    }

    /// The node one level up that covers `key`.
    pub fn parent(&self, key: NodeKey) -> Option<NodeKey> {
        if key.level == 0 {
            return None;
        }
        let s = self.split(key.level as u32);
        let c = key.coords();
        let up = |a: usize| c[a] >> s[a] as u32;
        Some(NodeKey::new(key.level - 1, up(0), up(1), up(2)))
    }

    /// The children's level halves these axes of a node at `level`; a node
    /// has 2^(their number) children.
    pub fn child_count(&self, level: u32) -> usize {
        1 << self.split(level + 1).iter().filter(|&&s| s).count()
    }

    /// The children of a node (some may lie outside the volume), in the
    /// order of their index c: its bits, lowest first, are the child's
    /// offset along each halved axis in x, y, z order.
    pub fn children(&self, key: NodeKey) -> impl Iterator<Item = NodeKey> {
        let s = self.split(key.level as u32 + 1);
        let c = key.coords();
        (0..self.child_count(key.level as u32) as u32).map(move |i| {
            let mut bit = 0;
            let k: [u32; 3] = std::array::from_fn(|a| {
                if s[a] {
                    let o = (i >> bit) & 1;
                    bit += 1;
                    2 * c[a] + o
                } else {
                    c[a]
                }
            });
            NodeKey::new(key.level + 1, k[0], k[1], k[2])
        })
    }

    /// The child index (see [`OctreeLayout::children`]) of the child of a
    /// level-`level` node whose coordinates on the child's level are `k`.
    pub fn child_index(&self, level: u32, k: [u64; 3]) -> u32 {
        let s = self.split(level + 1);
        let mut bit = 0;
        let mut i = 0;
        for a in 0..3 {
            if s[a] {
                i |= ((k[a] & 1) as u32) << bit;
                bit += 1;
            }
        }
        i
    }

    /// Values per side of a stored brick: B + 2·OVERLAP.
    pub fn stored_side(&self) -> usize {
        self.brick + 2 * OVERLAP
    }

    /// Values in a stored brick.
    pub fn stored_len(&self) -> usize {
        self.stored_side().pow(3)
    }

    /// Whether a node lies (at least partly) inside the volume.
    pub fn contains(&self, key: NodeKey) -> bool {
        if key.level as u32 >= self.levels {
            return false;
        }
        let n = self.level_bricks(key.level as u32);
        (key.x as usize) < n[0] && (key.y as usize) < n[1] && (key.z as usize) < n[2]
    }

    /// Total number of nodes inside the volume, all levels.
    pub fn node_count(&self) -> usize {
        (0..self.levels)
            .map(|l| self.level_bricks(l).iter().product::<usize>())
            .sum()
    }

    /// The part of a level's voxel grid a stored brick covers, as the first
    /// voxel index along each axis (may be negative: −OVERLAP at the volume's
    /// low edge; indices are clamped to the grid when values are gathered).
    pub fn brick_origin(&self, key: NodeKey) -> [i64; 3] {
        let b = self.brick as i64;
        [
            key.x as i64 * b - OVERLAP as i64,
            key.y as i64 * b - OVERLAP as i64,
            key.z as i64 * b - OVERLAP as i64,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_cover_the_volume() {
        let l = OctreeLayout::new([181, 217, 181], 32);
        // 32·2^3 = 256 ≥ 217 > 128
        assert_eq!(l.levels, 4);
        assert_eq!(l.level_dims(3), [181, 217, 181]);
        assert_eq!(l.level_dims(2), [91, 109, 91]);
        assert_eq!(l.level_dims(0), [23, 28, 23]);
        assert_eq!(l.level_bricks(3), [6, 7, 6]);
        assert_eq!(l.level_bricks(0), [1, 1, 1]);
        assert_eq!(l.level_bricks(2), [3, 4, 3]);
        assert_eq!(l.node_count(), 252 + 36 + 8 + 1);
        assert_eq!(OctreeLayout::new([32, 32, 32], 32).levels, 1);
        assert_eq!(OctreeLayout::new([1, 1, 1], 32).levels, 1);
        assert_eq!(OctreeLayout::new([33, 1, 1], 32).levels, 2);
    }

    #[test]
    fn children_and_parent() {
        let l = OctreeLayout::new([256, 256, 256], 32);
        let k = NodeKey::new(2, 3, 1, 2);
        assert_eq!(l.children(k).count(), 8);
        for (i, c) in l.children(k).enumerate() {
            assert_eq!(l.parent(c), Some(k));
            let cc = c.coords().map(|v| v as u64);
            assert_eq!(l.child_index(2, cc), i as u32);
        }
        assert_eq!(l.parent(NodeKey::root()), None);
    }

    #[test]
    fn thick_slices_halve_the_fine_axes_first() {
        // 0.5 × 0.5 × 4 mm: 1 × 1 × 4, 2 × 2 × 4, 4 × 4 × 4, then all.
        let l = OctreeLayout::for_spacing([512, 512, 64], 32, [0.5, 0.5, 4.0]);
        assert_eq!(l.levels, 5);
        assert_eq!(l.level_dims(4), [512, 512, 64]);
        assert_eq!(l.level_dims(3), [256, 256, 64]);
        assert_eq!(l.level_dims(2), [128, 128, 64]);
        assert_eq!(l.level_dims(1), [64, 64, 64]);
        assert_eq!(l.level_dims(0), [32, 32, 32]);
        assert_eq!(l.voxel_scale(2), [4, 4, 1]);
        assert_eq!(l.root_voxels(), [512, 512, 64]);
        assert_eq!(l.level_cells(2), [4, 4, 2]);
        assert_ne!(l, OctreeLayout::new(l.dims, l.brick));
        assert_eq!(l.child_count(0), 8);
        assert_eq!(l.child_count(2), 4);
        let k = NodeKey::new(2, 3, 1, 1);
        let kids: Vec<_> = l.children(k).collect();
        assert_eq!(kids.len(), 4);
        assert_eq!(kids[3], NodeKey::new(3, 7, 3, 1));
        for (i, c) in kids.into_iter().enumerate() {
            assert_eq!(l.parent(c), Some(k));
            assert_eq!(l.child_index(2, c.coords().map(|v| v as u64)), i as u32);
        }
        // Every node of every level has its parent in the level above.
        assert_eq!(
            l.node_count(),
            (0..5)
                .map(|v| l.level_bricks(v).iter().product::<usize>())
                .sum::<usize>()
        );
        // Near-cubic voxels: the isotropic octree.
        let iso = OctreeLayout::for_spacing([181, 217, 181], 32, [1.0, 1.0, 1.2]);
        assert_eq!(iso, OctreeLayout::new([181, 217, 181], 32));
        // A coarse axis with many voxels still ends under one root brick.
        let tall = OctreeLayout::for_spacing([40, 40, 1000], 16, [0.25, 0.25, 5.0]);
        assert!(tall.level_bricks(0) == [1, 1, 1]);
        assert!((0..3).all(|a| tall.root_voxels()[a] >= tall.dims[a]));
        // An axis down to one voxel no longer sets the pace: a single thick
        // slice, and a very fine axis, leave the others to be halved.
        let slab = OctreeLayout::for_spacing([512, 512, 1], 32, [0.5, 0.5, 4.0]);
        assert_eq!(slab.levels, 5);
        assert_eq!(slab.level_dims(0), [32, 32, 1]);
        // Thin but isotropic: the isotropic octree.
        let thin = OctreeLayout::for_spacing([1000, 2, 2], 4, [0.3; 3]);
        assert_eq!(thin, OctreeLayout::new([1000, 2, 2], 4));
        let fine = OctreeLayout::for_spacing([64, 64, 64], 8, [1e-3, 1.0, 1.0]);
        // x alone down to one voxel (6 levels), then y and z together (3).
        assert_eq!(fine.levels, 10);
        assert_eq!(fine.level_dims(3), [1, 64, 64]);
        assert_eq!(fine.level_dims(0), [1, 8, 8]);
        assert_eq!(fine.level_bricks(0), [1, 1, 1]);
    }
}
