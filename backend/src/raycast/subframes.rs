//! Frame reconstruction's filter on the GPU (G10 §5,
//! `shaders/reconstruct.wgsl`): the filter of [`crate::reconstruct`], run
//! on the frame's image buffer between the sub-frame's rays and the
//! read-back, so that what comes back is the reconstructed image and the
//! history never leaves the device. Each view's history lies where its
//! pixels lie in the image.

use super::Grown;
use crate::gpu::Gpu;
use crate::reconstruct::{DELTA_HIGH, DELTA_LOW, OFFSETS};
use anyhow::Result;

const HISTORY: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);
const VIEWS: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);
/// Invocations per workgroup (the shader's `@workgroup_size`).
const GROUP: u32 = 64;
/// Workgroups per row of the dispatch (within every device's limit).
const GROUPS_PER_ROW: u32 = 32_768;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    sub: [u32; 4],
    delta: [f32; 4],
}

pub(super) struct SubframeFilter {
    layout: wgpu::BindGroupLayout,
    /// PHASE 0, 1, 2 of the shader.
    pipelines: Vec<wgpu::ComputePipeline>,
    params: wgpu::Buffer,
    views: Grown,
    last: Grown,
    change: Grown,
    renders: Grown,
    /// The views' (width, height) the history was made for.
    layout_of: Vec<[u32; 2]>,
    /// The bind group and the image buffer's generation it names.
    bind: Option<(wgpu::BindGroup, u64)>,
}

/// The shader's bindings in order, by their WGSL names (binding i is the
/// i-th); a test checks them against naga's reflection.
#[cfg(test)]
const BINDINGS: [&str; 6] = ["params", "views", "image", "last", "change", "renders"];

/// The shader, validated without a GPU by the test below.
const SOURCE: &str = include_str!("../../../shaders/reconstruct.wgsl");

fn entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

impl SubframeFilter {
    pub(super) fn new(gpu: &Gpu) -> Result<Self> {
        let dev = &gpu.device;
        let rw = wgpu::BufferBindingType::Storage { read_only: false };
        let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("reconstruction"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform),
                entry(1, wgpu::BufferBindingType::Storage { read_only: true }),
                entry(2, rw),
                entry(3, rw),
                entry(4, rw),
                entry(5, rw),
            ],
        });
        let pipeline_layout = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("reconstruction"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = gpu.validated("shaders/reconstruct.wgsl", || {
            dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("reconstruct.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SOURCE.into()),
            })
        })?;
        let pipelines = (0..3)
            .map(|phase| {
                gpu.validated("reconstruction pipeline", || {
                    dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some("reconstruction"),
                        layout: Some(&pipeline_layout),
                        module: &module,
                        entry_point: Some("main"),
                        compilation_options: wgpu::PipelineCompilationOptions {
                            constants: &[("PHASE", phase as f64)],
                            ..Default::default()
                        },
                        cache: None,
                    })
                })
            })
            .collect::<Result<_>>()?;
        Ok(SubframeFilter {
            layout,
            pipelines,
            params: dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some("reconstruction parameters"),
                size: std::mem::size_of::<Params>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            views: Grown::new(gpu, "reconstruction views", VIEWS, 0),
            last: Grown::new(gpu, "reconstruction history", HISTORY, 0),
            change: Grown::new(gpu, "reconstruction history", HISTORY, 0),
            renders: Grown::new(gpu, "reconstruction history", HISTORY, 0),
            layout_of: Vec::new(),
            bind: None,
        })
    }

    /// Records the filter over `image` (generation `image_id`: it changes
    /// when the buffer is replaced) for views of `sizes`, whose pixels lie
    /// one after the other from pixel 0, sub-frame `k` just rendered into
    /// it. `reset`: start a new history (as a new
    /// [`crate::reconstruct::ViewHistory`]); it also starts anew when the
    /// views' sizes change.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        image: &wgpu::Buffer,
        image_id: u64,
        sizes: &[[u32; 2]],
        k: u32,
        reset: bool,
    ) {
        let pixels: u64 = sizes.iter().map(|s| s[0] as u64 * s[1] as u64).sum();
        let mut table = Vec::with_capacity(sizes.len());
        let (mut first, mut quads) = (0u32, 0u32);
        for &[w, h] in sizes {
            quads += w.div_ceil(2) * h.div_ceil(2);
            table.push([w, h, first, quads]);
            first += w * h;
        }
        let grown = [
            self.views
                .fit(gpu, "reconstruction views", VIEWS, 16 * table.len() as u64),
            self.last
                .fit(gpu, "reconstruction history", HISTORY, 16 * pixels),
            self.change
                .fit(gpu, "reconstruction history", HISTORY, 4 * pixels),
            self.renders
                .fit(gpu, "reconstruction history", HISTORY, 4 * pixels),
        ];
        let new_history = grown[1..].contains(&true) || self.layout_of != sizes;
        if new_history || reset {
            // As a new history on the CPU: no rendering, and black where a
            // pixel has no neighbour to take (a view one pixel wide).
            enc.clear_buffer(&self.renders.buffer, 0, Some(4 * pixels));
            enc.clear_buffer(&self.last.buffer, 0, Some(16 * pixels));
        }
        self.layout_of = sizes.to_vec();
        if grown.contains(&true) || !matches!(&self.bind, Some((_, id)) if *id == image_id) {
            let buffers = [
                &self.params,
                &self.views.buffer,
                image,
                &self.last.buffer,
                &self.change.buffer,
                &self.renders.buffer,
            ];
            let entries: Vec<wgpu::BindGroupEntry> = buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: b.as_entire_binding(),
                })
                .collect();
            let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("reconstruction"),
                layout: &self.layout,
                entries: &entries,
            });
            self.bind = Some((bind, image_id));
        }
        let [ox, oy] = OFFSETS[k as usize];
        let params = Params {
            sub: [ox, oy, table.len() as u32, quads],
            delta: [DELTA_LOW, DELTA_HIGH, 0.0, 0.0],
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        gpu.queue
            .write_buffer(&self.views.buffer, 0, bytemuck::cast_slice(&table));
        let groups = quads.div_ceil(GROUP);
        let bind = &self.bind.as_ref().expect("made above").0;
        // A pass per phase: each reads what the one before wrote.
        for pipeline in &self.pipelines {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(
                groups.min(GROUPS_PER_ROW),
                groups.div_ceil(GROUPS_PER_ROW),
                1,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `shaders/reconstruct.wgsl` parses and validates with naga, without a
    /// GPU, and declares the bindings the layout above makes, in order.
    #[test]
    fn the_filter_validates_and_its_bindings_match() {
        let got = super::super::bindings::reflect("reconstruct.wgsl", SOURCE);
        let want: Vec<(String, u32)> = BINDINGS
            .iter()
            .enumerate()
            .map(|(i, n)| (n.to_string(), i as u32))
            .collect();
        assert_eq!(got, want);
    }
}
