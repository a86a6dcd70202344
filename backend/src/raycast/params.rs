//! Structs shared with `shaders/shared/bindings.wgsl`: same field order and
//! sizes, checked against naga's layout of the WGSL by a test
//! (`raycast::shader`).

use bytemuck::{Pod, Zeroable};

/// WGSL `GpuView`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuView {
    /// x0, y0, w, h (m) on the screen plane.
    pub region: [f32; 4],
    /// E (m); w = η.
    pub eye: [f32; 4],
    /// V (m).
    pub observer: [f32; 4],
    /// W, H, first pixel in the output, 0.
    pub size: [u32; 4],
}

/// WGSL `GpuFrame`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuFrame {
    pub rt0: [f32; 4],
    pub rt1: [f32; 4],
    pub rt2: [f32; 4],
    /// placement centre (m); w = data units per metre.
    pub center: [f32; 4],
    pub extent: [f32; 4],
    pub domain: [f32; 4],
    /// s; w = min(s).
    pub spacing: [f32; 4],
    /// table vmin, bin width, bins.
    pub tf: [f32; 4],
    /// step factor, early-termination opacity, probe offset (root units).
    pub render: [f32; 4],
    /// Phong ka, kd, ks, shininess.
    pub light: [f32; 4],
    /// B, leaf level L, table levels, running-integral offset (0: none).
    pub counts: [u32; 4],
    /// slots per axis x, y, z; stored brick side.
    pub pool: [u32; 4],
    /// MImDA γ, the transfer function's largest importance.
    pub optics: [f32; 4],
    /// (ι, ν) table: first entry, running-integral offset (0: none).
    pub aux: [u32; 4],
    /// Isovalue and the surface's linear RGB colour (mode "iso").
    pub iso: [f32; 4],
    /// Prediction buffer: mode (0 off, 1 full traversal, 2 predicted),
    /// local window (data units), κ low, κ high (B10 §4).
    pub predict: [f32; 4],
    pub tf_offsets: [[u32; 4]; 8],
    /// Offset of the bin midpoint values in a table part.
    pub tf_mids: [u32; 4],
    /// Multilevel sampling: accuracy (pixels per voxel), light field s0
    /// (m), tan(Φ/2), light field (1) or not (0).
    pub lod: [f32; 4],
    /// The octree's split masks per axis (`OctreeLayout::splits`: bit l set
    /// where level l halves the axis), 0.
    pub splits: [u32; 4],
    /// Tiles listed (`tiles`), first texel of the index and of the tiles
    /// in the frame table, and how many of the tiles (listed first) meet a
    /// tool's region (`tiles::flag_regions`).
    pub dispatch: [u32; 4],
    /// 1 / the pool's texels along x, y, z; 1 / the table's bin width.
    pub recip: [f32; 4],
    /// The 2D table's lookup: table nodes per data unit ((n − 1) / (bins ·
    /// bin width)), n − 1, 1 / n, 0.
    pub grid: [f32; 4],
}

/// WGSL `LayerParams`: one registered layer's table, opacity and
/// view-dependent opacity (shaders/shared/layers.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct LayerParams {
    /// vmin, 1 / bin width, bins, opacity.
    pub table: [f32; 4],
    /// First entry in `tf_table`, the bin midpoints' first entry, the
    /// running integral's first entry (0: none), the pyramid's levels.
    pub at: [u32; 4],
    /// The view-dependent opacity's axis (volume space, unit); w: 1 where
    /// the layer has one.
    pub axis: [f32; 4],
    /// Its angles (radians): from, 1 / (to − from), 0, 0.
    pub angles: [f32; 4],
    /// Its (ι, ν) part of `tf_table` (MImDA): first entry, the running
    /// integral's first entry (0: none), 0, 0.
    pub aux: [u32; 4],
}

/// WGSL `ToolParams`: one tool's constant parameters (meaning per enhancer,
/// see `shaders/enhancers/`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ToolParams {
    pub a: [f32; 4],
    pub b: [f32; 4],
    pub c: [f32; 4],
    pub d: [f32; 4],
}
