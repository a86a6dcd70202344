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

    pub fn parent(self) -> Option<NodeKey> {
        (self.level > 0).then(|| NodeKey::new(self.level - 1, self.x / 2, self.y / 2, self.z / 2))
    }

    /// The eight possible children (some may lie outside the volume).
    pub fn children(self) -> [NodeKey; 8] {
        std::array::from_fn(|c| {
            NodeKey::new(
                self.level + 1,
                2 * self.x + (c as u32 & 1),
                2 * self.y + ((c as u32 >> 1) & 1),
                2 * self.z + ((c as u32 >> 2) & 1),
            )
        })
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OctreeLayout {
    pub dims: [usize; 3],
    pub brick: usize,
    /// Number of levels, L + 1 (the root is level 0, the source level L).
    pub levels: u32,
}

impl OctreeLayout {
    /// The smallest octree whose root, B·2^L voxels wide, covers the volume.
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
        }
    }

    /// L: the level that holds the source voxels.
    pub fn leaf_level(&self) -> u32 {
        self.levels - 1
    }

    /// Source voxels per level-`level` voxel along each axis: 2^(L−level).
    pub fn voxel_scale(&self, level: u32) -> usize {
        1usize << (self.leaf_level() - level)
    }

    /// Voxel grid of a level: ⌈dims / 2^(L−level)⌉ (each halving rounds up,
    /// so a coarse voxel at an odd edge averages fewer fine voxels).
    pub fn level_dims(&self, level: u32) -> [usize; 3] {
        let s = self.voxel_scale(level);
        self.dims.map(|d| d.div_ceil(s))
    }

    /// Bricks per axis at a level.
    pub fn level_bricks(&self, level: u32) -> [usize; 3] {
        self.level_dims(level).map(|d| d.div_ceil(self.brick))
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
        let k = NodeKey::new(2, 3, 1, 2);
        for c in k.children() {
            assert_eq!(c.parent(), Some(k));
        }
        assert_eq!(NodeKey::root().parent(), None);
    }
}
