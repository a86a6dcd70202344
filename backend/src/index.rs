//! The spatial index of the current cut (G10 §5 "GPU cache and spatial
//! index"): 6 × N 32-bit words, rebuilt on the CPU each frame and uploaded.
//!
//! Index nodes are laid out so that the children of a node are consecutive
//! (the first child's index is stored; child c = first + c, the bits of c
//! being the child's offset along each axis its level halves, x first:
//! c = x | y<<1 | z<<2 for eight children, `OctreeLayout::children`). The
//! six words of node i (`IndexNode`, mirrored by the
//! WGSL struct `IndexNode` in `shaders/raycast.wgsl`):
//!
//! | word | content |
//! |------|---------|
//! | 0 `tree`  | parent (low 16 bits) · first child (high 16 bits), `0xFFFF` = none |
//! | 1 `data`  | level (high 8 bits) · brick pool slot (low 24 bits), `0xFFFFFF` = no data |
//! | 2 `range` | the brick's [min, max] as two unorm16 of the dataset's value range (min low), rounded outwards |
//! | 3 `nx`    | neighbour across −x (low 16) · across +x (high 16) |
//! | 4 `ny`    | same for y |
//! | 5 `nz`    | same for z |
//!
//! A neighbour pointer leads to the node of the same level on the other side
//! of the face, or to its deepest ancestor in the index when that node is not
//! there (G08 §5); the ray then descends from it to the leaf that contains
//! its entry point. Every node keeps its data slot and range, so the ray
//! caster can also read parent and grandparent data (G10 §5).

use crate::store::{NodeKey, OctreeLayout};
use anyhow::{bail, Result};
use bytemuck::{Pod, Zeroable};
use std::collections::HashMap;

pub const NONE16: u32 = 0xFFFF;
pub const NO_SLOT: u32 = 0xFF_FFFF;
/// 16-bit node pointers, 0xFFFF reserved for "none".
pub const MAX_INDEX_NODES: usize = 0xFFFF;

/// One node of the index as the GPU reads it. WGSL: `struct IndexNode`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct IndexNode {
    pub tree: u32,
    pub data: u32,
    pub range: u32,
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
}

impl IndexNode {
    pub fn parent(&self) -> Option<u32> {
        some16(self.tree & 0xFFFF)
    }
    pub fn first_child(&self) -> Option<u32> {
        some16(self.tree >> 16)
    }
    pub fn level(&self) -> u32 {
        self.data >> 24
    }
    pub fn slot(&self) -> Option<u32> {
        let s = self.data & NO_SLOT;
        (s != NO_SLOT).then_some(s)
    }
    /// Neighbour across a face: axis 0..3, `plus` for the + side.
    pub fn neighbour(&self, axis: usize, plus: bool) -> Option<u32> {
        let w = [self.nx, self.ny, self.nz][axis];
        some16(if plus { w >> 16 } else { w & 0xFFFF })
    }
    /// The brick range decoded back to data values (outward-rounded).
    pub fn range(&self, global: (f32, f32)) -> (f32, f32) {
        let span = global.1 - global.0;
        (
            global.0 + (self.range & 0xFFFF) as f32 / 65535.0 * span,
            global.0 + (self.range >> 16) as f32 / 65535.0 * span,
        )
    }
}

fn some16(v: u32) -> Option<u32> {
    (v != NONE16).then_some(v)
}

/// What the index needs to know about one node of the cut.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutNode {
    /// Whether the node is refined: its children are in the index too.
    pub refined: bool,
    /// Brick pool slot of the node's data, if resident and worth sampling.
    pub slot: Option<u32>,
    pub min: f32,
    pub max: f32,
}

/// The index of one frame, and which octree node each index node is.
#[derive(Clone, Debug)]
pub struct SpatialIndex {
    pub nodes: Vec<IndexNode>,
    pub keys: Vec<NodeKey>,
    layout: OctreeLayout,
}

impl SpatialIndex {
    /// Builds the index of a cut. `cut` holds every node of the cut (inner
    /// and leaves) under its key; children of a refined node that are absent
    /// (outside the volume) become empty leaves. `global` is the dataset's
    /// value range, the frame of the unorm16 brick ranges.
    pub fn build(
        layout: &OctreeLayout,
        cut: &HashMap<NodeKey, CutNode>,
        global: (f32, f32),
    ) -> Result<Self> {
        let root = NodeKey::root();
        if !cut.contains_key(&root) {
            bail!("the cut has no root");
        }
        // Breadth-first: the children of a node get consecutive indices.
        let mut keys = vec![root];
        let mut parent = vec![NONE16];
        let mut first_child = Vec::new();
        let mut i = 0;
        while i < keys.len() {
            let k = keys[i];
            match cut.get(&k) {
                Some(n) if n.refined => {
                    first_child.push(keys.len() as u32);
                    for c in layout.children(k) {
                        keys.push(c);
                        parent.push(i as u32);
                    }
                }
                _ => first_child.push(NONE16),
            }
            if keys.len() > MAX_INDEX_NODES {
                bail!(
                    "the cut needs more than {MAX_INDEX_NODES} index nodes; lower the brick pool budget or raise `accuracy`"
                );
            }
            i += 1;
        }
        let at: HashMap<NodeKey, u32> = keys
            .iter()
            .enumerate()
            .map(|(i, k)| (*k, i as u32))
            .collect();
        let span = (global.1 - global.0).max(f32::MIN_POSITIVE);
        let unorm = |v: f32, up: bool| {
            let x = ((v - global.0) / span * 65535.0).clamp(0.0, 65535.0);
            (if up { x.ceil() } else { x.floor() }) as u32
        };
        let neighbour = |k: NodeKey, axis: usize, plus: bool| -> u32 {
            let mut c = [k.x as i64, k.y as i64, k.z as i64];
            c[axis] += if plus { 1 } else { -1 };
            let side = layout.level_cells(k.level as u32)[axis] as i64;
            if c[axis] < 0 || c[axis] >= side {
                return NONE16;
            }
            let mut n = NodeKey::new(k.level, c[0] as u32, c[1] as u32, c[2] as u32);
            loop {
                if let Some(&i) = at.get(&n) {
                    return i;
                }
                match layout.parent(n) {
                    Some(p) => n = p,
                    None => return NONE16,
                }
            }
        };
        let nodes = keys
            .iter()
            .enumerate()
            .map(|(i, &k)| {
                let c = cut.get(&k);
                let slot = c.and_then(|c| c.slot).unwrap_or(NO_SLOT);
                let (lo, hi) = c.map(|c| (c.min, c.max)).unwrap_or((global.0, global.0));
                let pair = |axis| neighbour(k, axis, false) | (neighbour(k, axis, true) << 16);
                IndexNode {
                    tree: parent[i] | (first_child[i] << 16),
                    data: ((k.level as u32) << 24) | slot,
                    range: unorm(lo, false) | (unorm(hi, true) << 16),
                    nx: pair(0),
                    ny: pair(1),
                    nz: pair(2),
                }
            })
            .collect();
        Ok(SpatialIndex {
            nodes,
            keys,
            layout: *layout,
        })
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The leaf containing a point of the root domain (coordinates in
    /// [0, 1)³), by descent from the root. The CPU twin of the ray caster's
    /// down traversal.
    pub fn leaf_at(&self, p: [f64; 3]) -> u32 {
        let mut i = 0u32;
        loop {
            let n = &self.nodes[i as usize];
            let Some(first) = n.first_child() else {
                return i;
            };
            let cells = self.layout.level_cells(n.level() + 1);
            let c: [u64; 3] = std::array::from_fn(|a| (p[a] * cells[a] as f64).floor() as u64);
            i = first + self.layout.child_index(n.level(), c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leaf(slot: Option<u32>) -> CutNode {
        CutNode {
            refined: false,
            slot,
            min: 0.0,
            max: 10.0,
        }
    }

    fn octree() -> OctreeLayout {
        OctreeLayout::new([32, 32, 32], 8)
    }

    /// A cut whose root (slot 0, values 0..max) is refined.
    fn refined_root(max: f32) -> HashMap<NodeKey, CutNode> {
        let root = CutNode {
            refined: true,
            max,
            ..leaf(Some(0))
        };
        HashMap::from([(NodeKey::root(), root)])
    }

    /// Root refined; child 0 refined again; others leaves.
    fn two_level_cut() -> HashMap<NodeKey, CutNode> {
        let l = octree();
        let mut cut = refined_root(100.0);
        let root = NodeKey::root();
        for (i, c) in l.children(root).enumerate() {
            cut.insert(
                c,
                CutNode {
                    refined: i == 0,
                    ..leaf(Some(1 + i as u32))
                },
            );
        }
        let first = l.children(root).next().unwrap();
        for (i, c) in l.children(first).enumerate() {
            cut.insert(c, leaf(if i == 7 { None } else { Some(20 + i as u32) }));
        }
        cut
    }

    #[test]
    fn layout_pointers_and_neighbours() {
        let idx = SpatialIndex::build(&octree(), &two_level_cut(), (0.0, 100.0)).unwrap();
        assert_eq!(idx.len(), 17);
        let root = idx.nodes[0];
        assert_eq!(root.parent(), None);
        assert_eq!(root.first_child(), Some(1));
        assert_eq!(root.slot(), Some(0));
        assert_eq!(root.range((0.0, 100.0)), (0.0, 100.0));
        // child 0 (index 1) is refined; its children are 9..17
        assert_eq!(idx.nodes[1].first_child(), Some(9));
        assert_eq!(idx.nodes[9].parent(), Some(1));
        assert_eq!(idx.nodes[9].level(), 2);
        assert_eq!(idx.nodes[16].slot(), None);
        // level-2 node (1,0,0) [index 10]: +x neighbour is level-2 (2,0,0),
        // not in the index → its ancestor, level-1 (1,0,0) = index 2.
        assert_eq!(idx.keys[10], NodeKey::new(2, 1, 0, 0));
        assert_eq!(idx.nodes[10].neighbour(0, true), Some(2));
        assert_eq!(idx.nodes[10].neighbour(0, false), Some(9));
        // −x of the domain edge: none
        assert_eq!(idx.nodes[9].neighbour(0, false), None);
        // level-1 (1,0,0): −x neighbour is level-1 (0,0,0), index 1
        assert_eq!(idx.nodes[2].neighbour(0, false), Some(1));
        // descent
        assert_eq!(idx.leaf_at([0.3, 0.1, 0.1]), 10);
        assert_eq!(idx.leaf_at([0.9, 0.1, 0.1]), 2);
        assert_eq!(idx.leaf_at([0.9, 0.9, 0.9]), 8);
    }

    #[test]
    fn ranges_round_outwards() {
        let mut cut = HashMap::new();
        cut.insert(
            NodeKey::root(),
            CutNode {
                refined: false,
                slot: Some(0),
                min: 0.123,
                max: 0.456,
            },
        );
        let idx = SpatialIndex::build(&octree(), &cut, (0.0, 1.0)).unwrap();
        let (lo, hi) = idx.nodes[0].range((0.0, 1.0));
        assert!(lo <= 0.123 && lo > 0.123 - 2e-5);
        assert!((0.456..0.456 + 2e-5).contains(&hi));
    }

    /// Thick slices: the root halves all axes, its children x and y only.
    #[test]
    fn anisotropic_levels_index_and_descend() {
        let l = OctreeLayout::for_spacing([32, 32, 16], 8, [1.0, 1.0, 2.0]);
        assert_eq!(l.levels, 3);
        assert_eq!(l.split(1), [true; 3]);
        assert_eq!(l.split(2), [true, true, false]);
        let mut cut = refined_root(10.0);
        let root = NodeKey::root();
        let kids: Vec<_> = l.children(root).collect();
        assert_eq!(kids.len(), 8);
        for (i, c) in kids.iter().enumerate() {
            cut.insert(
                *c,
                CutNode {
                    refined: i == 5,
                    ..leaf(Some(1 + i as u32))
                },
            );
        }
        // Node 5 is level-1 (1, 0, 1): four children on level 2 (2..3, 0..1, 1).
        let grand: Vec<_> = l.children(kids[5]).collect();
        assert_eq!(grand.len(), 4);
        assert_eq!(grand[3], NodeKey::new(2, 3, 1, 1));
        for (i, c) in grand.iter().enumerate() {
            cut.insert(*c, leaf(Some(20 + i as u32)));
        }
        let idx = SpatialIndex::build(&l, &cut, (0.0, 100.0)).unwrap();
        assert_eq!(idx.len(), 1 + 8 + 4);
        assert_eq!(idx.nodes[6].first_child(), Some(9));
        for (i, g) in grand.iter().enumerate() {
            assert_eq!(idx.keys[9 + i], *g);
            assert_eq!(idx.nodes[9 + i].parent(), Some(6));
        }
        // Descent: level-2 cells are 1/4 wide in x and y, 1/2 in z.
        assert_eq!(idx.leaf_at([0.55, 0.1, 0.6]), 9);
        assert_eq!(idx.leaf_at([0.8, 0.1, 0.9]), 10);
        assert_eq!(idx.leaf_at([0.8, 0.3, 0.9]), 12);
        assert_eq!(idx.leaf_at([0.3, 0.3, 0.9]), 5);
        // Level-2 (3, 1, 1): +x is outside the domain, −x is (2, 1, 1),
        // +y is level-2 (3, 2, 1), not in the index → its parent (1, 1, 1);
        // −z is level-2 (3, 1, 0) → level-1 (1, 0, 0).
        assert_eq!(idx.nodes[12].neighbour(0, true), None);
        assert_eq!(idx.nodes[12].neighbour(0, false), Some(11));
        assert_eq!(
            idx.keys[idx.nodes[12].neighbour(1, true).unwrap() as usize],
            NodeKey::new(1, 1, 1, 1)
        );
        assert_eq!(
            idx.keys[idx.nodes[12].neighbour(2, false).unwrap() as usize],
            NodeKey::new(1, 1, 0, 0)
        );
        assert_eq!(idx.nodes[12].neighbour(2, true), None);
    }
}
