//! Visibility from the last frame's feedback (G10 §5 "Visibility feedback and
//! adaptive loader").
//!
//! The renderer writes a non-zero word for index node i when it traversed
//! that node with data (a non-empty leaf contributed). Visibility is pulled up
//! to inner nodes: a node is visible when any of its descendants in the index
//! is. A node is *invisible* — not refined this frame — when it was in the
//! index, was not visible, and could have been seen: some leaf below it had
//! data to traverse. A subtree whose leaves were all empty says nothing about
//! occlusion (no ray could mark it), so it is not held back; this keeps a node
//! refined into empty children from collapsing back to its coarse, non-empty
//! brick and oscillating. Nodes not in the last index count as visible.

use crate::index::SpatialIndex;
use crate::store::NodeKey;
use std::collections::HashSet;

#[derive(Debug, Default)]
pub(crate) struct Visibility {
    invisible: HashSet<NodeKey>,
    /// Index nodes visible after the pull-up.
    pub visible: usize,
}

impl Visibility {
    /// No feedback: everything counts as visible.
    pub fn none() -> Self {
        Self::default()
    }

    /// Several frames' feedback: invisible where every frame found it so.
    pub fn from_feedbacks(frames: &[(&SpatialIndex, &[u32])]) -> Self {
        let mut it = frames.iter().map(|(i, f)| Self::from_feedback(i, f));
        let Some(mut v) = it.next() else {
            return Self::none();
        };
        for other in it {
            v.invisible.retain(|k| other.invisible.contains(k));
            v.visible = v.visible.max(other.visible);
        }
        v
    }

    /// `feedback[i]` belongs to index node i; entries beyond the index are
    /// ignored and missing entries count as zero.
    pub fn from_feedback(index: &SpatialIndex, feedback: &[u32]) -> Self {
        let n = index.nodes.len().min(index.keys.len());
        let mut visible = vec![false; n];
        let mut could_see = vec![false; n];
        // Breadth-first layout: children come after their parent, so a
        // reverse sweep finishes every subtree before its root.
        for i in (0..n).rev() {
            let node = &index.nodes[i];
            if feedback.get(i).is_some_and(|&f| f != 0) {
                visible[i] = true;
                could_see[i] = true;
            }
            if node.first_child().is_none() && node.slot().is_some() {
                could_see[i] = true;
            }
            if let Some(p) = node.parent() {
                let p = p as usize;
                if p < i {
                    visible[p] |= visible[i];
                    could_see[p] |= could_see[i];
                }
            }
        }
        let invisible = (0..n)
            .filter(|&i| could_see[i] && !visible[i])
            .map(|i| index.keys[i])
            .collect();
        Visibility {
            invisible,
            visible: visible.iter().filter(|&&v| v).count(),
        }
    }

    pub fn is_invisible(&self, key: NodeKey) -> bool {
        self.invisible.contains(&key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::CutNode;
    use std::collections::HashMap;

    #[test]
    fn pull_up_and_empty_subtrees() {
        // root refined; child 0 refined (its children: 0..6 with data, 7
        // empty); child 1 refined into empty leaves only; others leaves with
        // data.
        let root = NodeKey::root();
        let mut cut = HashMap::new();
        let data = |slot| CutNode {
            refined: false,
            slot: Some(slot),
            min: 0.0,
            max: 1.0,
        };
        cut.insert(
            root,
            CutNode {
                refined: true,
                ..data(0)
            },
        );
        let l = crate::store::OctreeLayout::new([32, 32, 32], 8);
        let ch = |k: NodeKey| l.children(k).collect::<Vec<_>>();
        let kids = ch(root);
        for (i, c) in kids.iter().copied().enumerate() {
            cut.insert(
                c,
                CutNode {
                    refined: i < 2,
                    ..data(1 + i as u32)
                },
            );
        }
        for (i, c) in ch(kids[0]).into_iter().enumerate() {
            cut.insert(
                c,
                if i == 7 {
                    CutNode {
                        slot: None,
                        ..data(0)
                    }
                } else {
                    data(10 + i as u32)
                },
            );
        }
        for c in ch(kids[1]) {
            cut.insert(
                c,
                CutNode {
                    slot: None,
                    ..data(0)
                },
            );
        }
        let idx = SpatialIndex::build(&l, &cut, (0.0, 1.0)).unwrap();
        let at = |k: NodeKey| idx.keys.iter().position(|&x| x == k).unwrap();
        let mut fb = vec![0u32; idx.len()];
        fb[at(ch(kids[0])[3])] = 1;
        let vis = Visibility::from_feedback(&idx, &fb);
        assert!(!vis.is_invisible(root));
        assert!(!vis.is_invisible(kids[0]));
        assert!(!vis.is_invisible(ch(kids[0])[3]));
        assert!(vis.is_invisible(ch(kids[0])[2]));
        // empty leaf and a subtree of empty leaves: no evidence either way
        assert!(!vis.is_invisible(ch(kids[0])[7]));
        assert!(!vis.is_invisible(kids[1]));
        // leaves with data never traversed
        for c in &kids[2..] {
            assert!(vis.is_invisible(*c));
        }
        // not in the index: visible
        assert!(!vis.is_invisible(ch(kids[2])[0]));
        assert_eq!(vis.visible, 3);
        // a short feedback array: missing entries are zero
        let vis = Visibility::from_feedback(&idx, &fb[..2]);
        assert!(vis.is_invisible(kids[0]));
        assert_eq!(vis.visible, 0);
    }
}
