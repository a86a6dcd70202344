//! The ray caster's bind group layout: one entry per `@binding` of
//! `shaders/shared/bindings.wgsl`.

use super::frame::FrameBuffers;
use super::texels;
use super::tf_table::TfTable;
use super::BrickPool;
use crate::gpu::Gpu;

/// The kernel's bindings by their WGSL names; a test checks them against
/// naga's reflection of every kernel combination.
pub(super) const FRAME_CONSTANTS: u32 = 0;
pub(super) const FRAME_TABLE: u32 = 1;
pub(super) const POOL: u32 = 3;
pub(super) const SLOT_TABLE: u32 = 4;
pub(super) const TF_TABLE: u32 = 5;
pub(super) const FEEDBACK: u32 = 6;
pub(super) const IMAGE: u32 = 7;
pub(super) const POOL_SAMPLER: u32 = 8;
pub(super) const TOOL_CONSTANTS: u32 = 9;
pub(super) const PREDICTION: u32 = 10;
pub(super) const COUNTERS: u32 = 11;
pub(super) const PREINT_GRID: u32 = 12;
pub(super) const GRID_SAMPLER: u32 = 13;
pub(super) const TF_PIECES_CONSTANTS: u32 = 14;
pub(super) const LAYER_CONSTANTS: u32 = 15;

/// Every binding with its WGSL name.
#[cfg(test)]
pub(super) const NAMED: [(&str, u32); 15] = [
    ("frame_constants", FRAME_CONSTANTS),
    ("frame_table", FRAME_TABLE),
    ("pool", POOL),
    ("slot_table", SLOT_TABLE),
    ("tf_table", TF_TABLE),
    ("feedback", FEEDBACK),
    ("image", IMAGE),
    ("pool_sampler", POOL_SAMPLER),
    ("tool_constants", TOOL_CONSTANTS),
    ("prediction", PREDICTION),
    ("counters", COUNTERS),
    ("preint_grid", PREINT_GRID),
    ("grid_sampler", GRID_SAMPLER),
    ("tf_pieces_constants", TF_PIECES_CONSTANTS),
    ("layer_constants", LAYER_CONSTANTS),
];

/// The kernel's bind group layout: bricks filtered by the texture unit or
/// not, the 2D table filterable or not.
pub(super) fn layout(gpu: &Gpu, hw_filter: bool, grid_filterable: bool) -> wgpu::BindGroupLayout {
    gpu.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("raycast"),
            entries: &[
                storage(FRAME_CONSTANTS, true),
                texels::layout_entry(FRAME_TABLE),
                texture(POOL, wgpu::TextureViewDimension::D3, hw_filter),
                texels::layout_entry(SLOT_TABLE),
                texels::layout_entry(TF_TABLE),
                storage(FEEDBACK, false),
                storage(IMAGE, false),
                sampler(POOL_SAMPLER, hw_filter),
                storage(TOOL_CONSTANTS, true),
                storage(PREDICTION, false),
                storage(COUNTERS, false),
                texture(PREINT_GRID, wgpu::TextureViewDimension::D2, grid_filterable),
                sampler(GRID_SAMPLER, grid_filterable),
                storage(TF_PIECES_CONSTANTS, true),
                storage(LAYER_CONSTANTS, true),
            ],
        })
}

/// What the kernel's bind group binds besides the frame's buffers.
pub(super) struct Bound<'a> {
    pub pool: &'a BrickPool,
    pub tf: &'a TfTable,
    pub sampler: &'a wgpu::Sampler,
    pub tools: &'a wgpu::Buffer,
    pub grid: &'a wgpu::TextureView,
    pub grid_sampler: &'a wgpu::Sampler,
    pub layers: &'a wgpu::Buffer,
}

/// The kernel's bind group over the frame's buffers, the pool and the
/// transfer function's tables.
pub(super) fn group(
    gpu: &Gpu,
    layout: &wgpu::BindGroupLayout,
    fr: &FrameBuffers,
    b: &Bound,
) -> wgpu::BindGroup {
    use wgpu::BindingResource::{Sampler, TextureView};
    let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("raycast"),
        layout,
        entries: &[
            entry(FRAME_CONSTANTS, fr.constants.as_entire_binding()),
            entry(FRAME_TABLE, TextureView(&fr.table.view)),
            entry(POOL, TextureView(&b.pool.view)),
            entry(SLOT_TABLE, TextureView(&b.pool.slots.view)),
            entry(TF_TABLE, TextureView(&b.tf.buffer.view)),
            entry(FEEDBACK, fr.feedback.buffer.as_entire_binding()),
            entry(IMAGE, fr.image.buffer.as_entire_binding()),
            entry(POOL_SAMPLER, Sampler(b.sampler)),
            entry(TOOL_CONSTANTS, b.tools.as_entire_binding()),
            entry(PREDICTION, fr.prediction.buffer.as_entire_binding()),
            entry(COUNTERS, fr.counters.as_entire_binding()),
            entry(PREINT_GRID, TextureView(b.grid)),
            entry(GRID_SAMPLER, Sampler(b.grid_sampler)),
            entry(TF_PIECES_CONSTANTS, b.tf.pieces.as_entire_binding()),
            entry(LAYER_CONSTANTS, b.layers.as_entire_binding()),
        ],
    })
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn texture(
    binding: u32,
    view_dimension: wgpu::TextureViewDimension,
    filterable: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension,
            multisampled: false,
        },
        count: None,
    }
}

fn sampler(binding: u32, filtering: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Sampler(if filtering {
            wgpu::SamplerBindingType::Filtering
        } else {
            wgpu::SamplerBindingType::NonFiltering
        }),
        count: None,
    }
}

/// A clamping sampler, bilinear or nearest.
pub(super) fn make_sampler(gpu: &Gpu, label: &str, linear: bool) -> wgpu::Sampler {
    let filter = if linear {
        wgpu::FilterMode::Linear
    } else {
        wgpu::FilterMode::Nearest
    };
    gpu.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some(label),
        mag_filter: filter,
        min_filter: filter,
        ..Default::default()
    })
}

/// `(name, binding)` of every bound global of a WGSL module, by naga's
/// reflection, sorted by binding.
#[cfg(test)]
pub(super) fn reflect(what: &str, src: &str) -> Vec<(String, u32)> {
    use wgpu::naga;
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{what}:\n{}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{what}:\n{}", e.emit_to_string(src)));
    let mut out: Vec<(String, u32)> = module
        .global_variables
        .iter()
        .filter_map(|(_, g)| {
            let b = g.binding.as_ref()?;
            assert_eq!(b.group, 0, "{what}: everything is in group 0");
            Some((g.name.clone().unwrap_or_default(), b.binding))
        })
        .collect();
    out.sort_by_key(|&(_, b)| b);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raycast::shader::{kernel, KernelKey};

    /// The layout's and the bind group's numbers are those the WGSL
    /// declares, for every kernel combination (naga's reflection, no GPU).
    #[test]
    fn bindings_match_the_kernel() {
        let want: Vec<(String, u32)> = NAMED.iter().map(|&(n, b)| (n.to_string(), b)).collect();
        for key in [
            KernelKey::default(),
            KernelKey::all().pop().expect("combinations"),
        ] {
            let src = kernel(&key).unwrap();
            assert_eq!(reflect(&format!("{key:?}"), &src), want, "{key:?}");
        }
    }
}
