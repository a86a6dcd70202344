//! Where the volume is: its octree's shape and voxel spacing in volume
//! space (data length units), and its placement in display space
//! (docs/design.md "Volume space"). The loader, the tile list and the
//! kernel's constants all read this one description.

use crate::store::{NodeKey, OctreeLayout};
use glam::DVec3;
use parallax_common::camera::Placement;

/// The static geometry of a database: its octree's layout, the voxel
/// spacing and the volume's extent N·s in volume space (data units), the
/// one place the extent is computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    pub layout: OctreeLayout,
    pub spacing: [f64; 3],
    pub extent: [f64; 3],
}

impl Geometry {
    pub fn new(layout: OctreeLayout, spacing: [f64; 3]) -> Self {
        let extent = crate::volume::extent(layout.dims, spacing);
        Geometry {
            layout,
            spacing,
            extent,
        }
    }

    /// The node's region of the volume, [lo, hi] in volume space (data
    /// units): brick · scale · spacing · [x, x+1] along each axis (scale:
    /// source voxels per level voxel), clamped to the extent.
    pub fn node_box(&self, key: NodeKey) -> (DVec3, DVec3) {
        let scale = self.layout.voxel_scale(key.level as u32);
        let c = [key.x, key.y, key.z];
        let span = |a: usize| (self.layout.brick * scale[a]) as f64 * self.spacing[a];
        let lo: [f64; 3] = std::array::from_fn(|a| (c[a] as f64 * span(a)).min(self.extent[a]));
        let hi: [f64; 3] =
            std::array::from_fn(|a| ((c[a] as f64 + 1.0) * span(a)).min(self.extent[a]));
        (DVec3::from(lo), DVec3::from(hi))
    }

    /// The size of a level-`level` voxel that refinement compares with a
    /// pixel, in data units: the longest of its edges along the axes its
    /// children halve, max over split(level + 1) of scale · spacing, above
    /// the leaves; a leaf's finest edge, min(spacing), at the leaves (they
    /// cannot be refined; the figure only reports how closely they are
    /// seen).
    ///
    /// L12 §4.2 refines a node while its voxels project to more than a
    /// pixel: while refining would show detail the pixel can resolve. What
    /// refining a node shows is its children's halving, so the edges it
    /// shortens are the ones to measure; an edge no child halves cannot get
    /// finer whatever the view. On levels halving every axis this is the
    /// longest edge. On thick slices (a CT of 0.57 × 0.57 × 5 mm, whose
    /// levels from `OctreeLayout::for_spacing` halve the in-plane axes
    /// first: 0.57, 1.14, 2.28 and 4.56 mm in-plane, all 5 mm thick) the
    /// longest edge is 5 mm on all four, so a view could only have all of
    /// them or none: sized by what their children halve (4.56, 2.28, 1.14
    /// mm, then the leaf's 0.57), each level is reached at its own
    /// distance, and `accuracy` moves through them. Thick slices are never
    /// blurred by it: a level that coarsens the 5 mm axis (9.1 × 9.1 × 10
    /// mm) halves every axis, and is sized by its longest edge, 10 mm, as
    /// before.
    pub fn voxel_len(&self, level: u32) -> f64 {
        if level >= self.layout.leaf_level() {
            return self.spacing.iter().cloned().fold(f64::INFINITY, f64::min);
        }
        let scale = self.layout.voxel_scale(level);
        let split = self.layout.split(level + 1);
        let edge = |a: usize| scale[a] as f64 * self.spacing[a];
        let refined = (0..3).filter(|&a| split[a]).map(edge).fold(0.0, f64::max);
        if refined > 0.0 {
            refined
        } else {
            (0..3).map(edge).fold(0.0, f64::max)
        }
    }
}

/// A database's geometry placed in display space for a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneGeometry {
    pub geom: Geometry,
    pub placement: Placement,
}

impl SceneGeometry {
    pub fn new(placement: Placement, layout: OctreeLayout, spacing: [f64; 3]) -> Self {
        SceneGeometry {
            geom: Geometry::new(layout, spacing),
            placement,
        }
    }

    /// The volume's box N·s (data units).
    pub fn extent(&self) -> [f64; 3] {
        self.geom.extent
    }

    /// Display metres per data unit.
    pub fn scale(&self) -> f64 {
        self.placement.scale(self.geom.extent)
    }

    /// A volume-space point in display space.
    pub fn to_display(&self, p: DVec3) -> DVec3 {
        self.placement.to_display(self.geom.extent, p)
    }
}
