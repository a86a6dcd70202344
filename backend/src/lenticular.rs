//! A Looking Glass's panel image from its views, on the GPU
//! (`shaders/lenticular.wgsl`; the mapping of
//! [`parallax_common::lenticular`]).

use crate::gpu::Gpu;
use anyhow::{ensure, Result};
use parallax_common::lenticular::LookingGlass;
use wgpu::util::DeviceExt;

/// The shader, validated without a GPU by a test.
const SOURCE: &str = include_str!("../../shaders/lenticular.wgsl");

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    size: [u32; 4],
    views: [u32; 4],
    map: [f32; 4],
    inv: [u32; 4],
}

/// The interleaving pipeline, made once per back end.
pub struct Interleaver {
    pipeline: wgpu::ComputePipeline,
}

impl Interleaver {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        let module = gpu.validated("shaders/lenticular.wgsl", || {
            gpu.device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("lenticular.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(SOURCE.into()),
                })
        })?;
        let pipeline = gpu.validated("the lenticular pipeline", || {
            gpu.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("lenticular"),
                    layout: None,
                    module: &module,
                    entry_point: Some("main"),
                    compilation_options: Default::default(),
                    cache: None,
                })
        })?;
        Ok(Interleaver { pipeline })
    }

    /// The panel (screen W × H, row 0 at the top, linear premultiplied) of
    /// the device `lg` showing `views` (each `size`, in view order).
    pub fn panel(
        &self,
        gpu: &Gpu,
        lg: &LookingGlass,
        views: &[Vec<[f32; 4]>],
        size: [u32; 2],
    ) -> Result<Vec<[f32; 4]>> {
        let n = lg.views();
        ensure!(
            views.len() == n as usize,
            "Looking Glass: {} views for a quilt of {n}",
            views.len()
        );
        let texels = (size[0] * size[1]) as usize;
        ensure!(
            views.iter().all(|v| v.len() == texels),
            "Looking Glass: every view must be {}×{}",
            size[0],
            size[1]
        );
        let l = lg.lenticular();
        let [pw, ph] = lg.screen;
        let params = Params {
            size: [pw, ph, size[0], size[1]],
            views: [n, lg.flip_x as u32, lg.flip_y as u32, lg.flip_subp as u32],
            map: [
                l.pitch as f32,
                l.tilt as f32,
                l.subp as f32,
                l.center as f32,
            ],
            inv: [lg.inv_view as u32, 0, 0, 0],
        };
        let dev = &gpu.device;
        let all: Vec<[f32; 4]> = views.concat();
        let bytes = (pw as u64) * (ph as u64) * 16;
        let limit = dev.limits().max_storage_buffer_binding_size;
        ensure!(
            bytes <= limit && all.len() as u64 * 16 <= limit,
            "Looking Glass: a {pw}×{ph} panel or its views exceed the GPU's storage binding limit"
        );
        let uniform = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("lenticular parameters"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let input = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("views"),
            contents: bytemuck::cast_slice(&all),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let output = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("panel"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("panel readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("lenticular"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: input.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: output.as_entire_binding(),
                },
            ],
        });
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(pw.div_ceil(8), ph.div_ceil(8), 1);
        }
        enc.copy_buffer_to_buffer(&output, 0, &readback, 0, bytes);
        gpu.queue.submit([enc.finish()]);
        let data = gpu.map_read(readback.slice(..), "the panel")?;
        let px: Vec<[f32; 4]> = bytemuck::cast_slice(&data).to_vec();
        drop(data);
        readback.unmap();
        Ok(px)
    }
}

#[cfg(test)]
mod tests {
    /// The shader parses and validates with naga, without a GPU.
    #[test]
    fn the_shader_validates() {
        let m = wgpu::naga::front::wgsl::parse_str(super::SOURCE).unwrap();
        wgpu::naga::valid::Validator::new(
            wgpu::naga::valid::ValidationFlags::all(),
            wgpu::naga::valid::Capabilities::all(),
        )
        .validate(&m)
        .unwrap();
    }
}
