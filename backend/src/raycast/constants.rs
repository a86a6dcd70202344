//! The frame's constants as the kernel reads them (`GpuFrame`,
//! `shaders/shared/bindings.wgsl`): the placement, the octree's shape, the
//! transfer function's table layout and the quality knobs.

use super::params::GpuFrame;
use super::{BrickPool, RenderSettings, SceneGeometry, TfTable};

/// The frame's constants; the dispatch's tiles are filled in later.
pub(super) fn frame_constants(
    pool: &BrickPool,
    tf: &TfTable,
    scene: &SceneGeometry,
    s: &RenderSettings,
) -> GpuFrame {
    let ext = scene.extent();
    let pl = &scene.placement;
    let rt = pl.rotation().transpose();
    let col = |c: glam::DVec3| [c.x as f32, c.y as f32, c.z as f32, 0.0];
    let l = &scene.geom.layout;
    let root = l.root_voxels().map(|v| v as f64);
    let sp = scene.geom.spacing;
    let mut tf_offsets = [[0u32; 4]; 8];
    for (k, &o) in tf.layout.level_offsets.iter().enumerate() {
        tf_offsets[k / 4][k % 4] = o;
    }
    GpuFrame {
        rt0: col(rt.x_axis),
        rt1: col(rt.y_axis),
        rt2: col(rt.z_axis),
        center: [
            pl.center[0] as f32,
            pl.center[1] as f32,
            pl.center[2] as f32,
            (1.0 / pl.scale(ext)) as f32,
        ],
        extent: [ext[0] as f32, ext[1] as f32, ext[2] as f32, s.sub_pixel],
        domain: [
            (root[0] * sp[0]) as f32,
            (root[1] * sp[1]) as f32,
            (root[2] * sp[2]) as f32,
            0.0,
        ],
        spacing: [
            sp[0] as f32,
            sp[1] as f32,
            sp[2] as f32,
            sp.iter().cloned().fold(f64::INFINITY, f64::min) as f32,
        ],
        tf: [
            tf.layout.vmin as f32,
            tf.layout.bin_width as f32,
            tf.layout.n_bins as f32,
            tf.grid.as_ref().map_or(0.0, |g| g.2 as f32),
        ],
        render: [
            s.step_factor,
            s.early_termination,
            (0.01 / root.iter().cloned().fold(0.0, f64::max)) as f32,
            if s.adaptive_step { 1.0 } else { 0.0 },
        ],
        light: [0.35, 0.65, 0.25, 24.0],
        counts: [
            l.brick as u32,
            l.leaf_level(),
            tf.layout.levels,
            tf.prefix_offset,
        ],
        pool: [pool.grid[0], pool.grid[1], pool.grid[2], pool.side],
        optics: [
            s.gamma,
            tf.max_importance,
            if s.record_depth { 1.0 } else { 0.0 },
            s.refine_parts() as f32,
        ],
        aux: [
            tf.aux_base,
            tf.aux_prefix,
            pool.cells.per_axis,
            pool.cells.voxels,
        ],
        iso: s.iso,
        predict: s.predict,
        tf_offsets,
        tf_mids: [tf.layout.mid_offset, 0, 0, 0],
        lod: match s.multilevel {
            None => [0.0; 4],
            Some(m) => {
                let (s0, tan_half) = m.lightfield.unwrap_or((0.0, 0.0));
                let lf = if m.lightfield.is_some() { 1.0 } else { 0.0 };
                [m.accuracy, s0, tan_half, lf]
            }
        },
        splits: [l.splits[0], l.splits[1], l.splits[2], 0],
        dispatch: [0; 4],
        recip: {
            let t = |k: usize| 1.0 / (pool.grid[k] * pool.side) as f32;
            [t(0), t(1), t(2), (1.0 / tf.layout.bin_width) as f32]
        },
        grid: {
            let n = tf.grid.as_ref().map_or(0.0, |g| g.2 as f32);
            [
                (n - 1.0) / tf.layout.n_bins as f32 / tf.layout.bin_width as f32,
                n - 1.0,
                1.0 / n.max(1.0),
                0.0,
            ]
        },
    }
}
