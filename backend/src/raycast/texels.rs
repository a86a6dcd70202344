//! Read-only tables the kernel reads per ray, per leaf or per macrocell
//! step, kept in a 2D `rgba32uint` texture of [`ROW`] texels a row and
//! read with `textureLoad` (WGSL `texel_at`, shaders/shared/bindings.wgsl).
//!
//! A texel fetch is one vector gather per channel on every device. A
//! storage-buffer read is too on a GPU, but a CPU device (lavapipe) reads
//! a storage buffer one lane and one word at a time, each behind its own
//! branch. Views, index nodes, tiles and slot entries read as texels
//! instead took the Colin27 skin at 8 mm from 46.6 to 33.3 ms a frame and
//! the translucent brain at 5 mm from 105 to 84.5 ms, the image bit for
//! bit the same (docs/performance.md, "Kernel changes on a CPU device").

use crate::gpu::Gpu;

/// Texels per row (a power of two: the kernel splits an index with a mask
/// and a shift). Narrow on purpose: with rows of 4096 texels (64 KiB)
/// lavapipe's resident memory grew by about half a MiB with every dispatch
/// that bound such a texture, whether or not the kernel read it, and the
/// tables were written or not; with rows of 256 it stays flat (the live
/// soak test, tests/live.rs).
pub const ROW: u32 = 256;

/// A texture of `[u32; 4]` texels addressed by one linear index, grown by
/// whole rows.
pub struct TexelTable {
    label: &'static str,
    texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    rows: u32,
}

impl TexelTable {
    pub fn new(gpu: &Gpu, label: &'static str, texels: u64) -> Self {
        let rows = (texels.div_ceil(ROW as u64) as u32).max(1);
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: ROW,
                height: rows,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        TexelTable {
            label,
            texture,
            view,
            rows,
        }
    }

    /// Texels it holds.
    pub fn capacity(&self) -> u64 {
        self.rows as u64 * ROW as u64
    }

    /// Makes room for `texels` (contents are lost when it grows); true when
    /// it grew, so that bind groups over it are made anew.
    pub fn fit(&mut self, gpu: &Gpu, texels: u64) -> bool {
        if texels <= self.capacity() {
            return false;
        }
        *self = TexelTable::new(gpu, self.label, texels);
        true
    }

    /// Writes `data` from texel `first` on (it must fit).
    pub fn write(&self, gpu: &Gpu, first: u64, data: &[[u32; 4]]) {
        debug_assert!(first + data.len() as u64 <= self.capacity());
        let row = ROW as u64;
        let (mut at, mut rest) = (first, data);
        while !rest.is_empty() {
            let x = (at % row) as u32;
            // A part row up to the row's end, else as many whole rows as
            // there are (one copy), else the last part row.
            let n = if x != 0 || (rest.len() as u64) < row {
                ((row - x as u64) as usize).min(rest.len())
            } else {
                rest.len() - rest.len() % ROW as usize
            };
            let (now, later) = rest.split_at(n);
            let (width, height) = if n as u64 >= row {
                (ROW, (n as u64 / row) as u32)
            } else {
                (n as u32, 1)
            };
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &self.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x,
                        y: (at / row) as u32,
                        z: 0,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(now),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(width * 16),
                    rows_per_image: None,
                },
                wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
            );
            at += n as u64;
            rest = later;
        }
    }
}

impl TexelTable {
    /// Copies the first `rows` rows from `staging` (texels packed in whole
    /// rows from its start) in the frame's command encoder: a table
    /// rewritten every frame goes through a buffer of its own, one copy.
    pub fn copy_rows(&self, enc: &mut wgpu::CommandEncoder, staging: &wgpu::Buffer, rows: u32) {
        if rows == 0 {
            return;
        }
        enc.copy_buffer_to_texture(
            wgpu::TexelCopyBufferInfo {
                buffer: staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(ROW * 16),
                    rows_per_image: None,
                },
            },
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::Extent3d {
                width: ROW,
                height: rows,
                depth_or_array_layers: 1,
            },
        );
    }
}

/// The bind group layout entry of a table at `binding`.
pub fn layout_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}
