//! The GPU brick pool (G08 §4, G10 §5): one 3D texture cut into slots of
//! (B+4)³ texels, plus each slot's value range. 8-bit pools store each brick
//! quantised against its own range (G10 §5) in `r8unorm`; full-precision
//! pools store data values in `r32float`.

use crate::gpu::Gpu;
use anyhow::{bail, Result};

/// What a no-data voxel is in a float pool (the kernel's `NO_DATA_TAP`
/// threshold is 1e38 there).
pub const NO_DATA_VALUE: f32 = 3.0e38;

pub struct BrickPool {
    pub(crate) texture: wgpu::Texture,
    pub(crate) view: wgpu::TextureView,
    pub(crate) ranges: wgpu::Buffer,
    /// Slots along x, y, z.
    pub grid: [u32; 3],
    /// Texels per side of a slot.
    pub side: u32,
    /// Full precision (`r32float`) or 8 bit (`r8unorm`).
    pub float: bool,
    /// Some uploaded brick had no-data voxels (NaN): the kernel must
    /// leave them out of its interpolation.
    pub no_data: bool,
    uploaded: u64,
    /// Which pool this is (a bind group names one pool).
    pub(crate) id: u64,
}

impl BrickPool {
    /// Bytes one slot takes.
    pub fn slot_bytes(side: u32, float: bool) -> u64 {
        side as u64 * side as u64 * side as u64 * if float { 4 } else { 1 }
    }

    /// The most slots a byte budget buys.
    pub fn slots_for_budget(budget_bytes: u64, side: u32, float: bool) -> u32 {
        (budget_bytes / Self::slot_bytes(side, float)).min(u32::MAX as u64) as u32
    }

    pub fn new(gpu: &Gpu, slots: u32, side: u32, float: bool) -> Result<Self> {
        if slots == 0 {
            bail!(
                "the GPU brick pool budget is too small for even one brick ({} KiB per brick)",
                Self::slot_bytes(side, float) / 1024
            );
        }
        let max = gpu.device.limits().max_texture_dimension_3d / side;
        // A near-cubic grid of slots within the 3D texture limit.
        let mut grid = [1u32; 3];
        while grid.iter().product::<u32>() < slots {
            let a = (0..3).min_by_key(|&a| grid[a]).unwrap();
            if grid[a] >= max {
                bail!("a brick pool of {slots} slots does not fit in a 3D texture ({max} slots per side)");
            }
            grid[a] += 1;
        }
        let format = if float {
            wgpu::TextureFormat::R32Float
        } else {
            wgpu::TextureFormat::R8Unorm
        };
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("brick pool"),
            size: wgpu::Extent3d {
                width: grid[0] * side,
                height: grid[1] * side,
                depth_or_array_layers: grid[2] * side,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let ranges = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brick ranges"),
            size: grid.iter().product::<u32>() as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(BrickPool {
            texture,
            view,
            ranges,
            grid,
            side,
            float,
            no_data: false,
            uploaded: 0,
            id: super::next_resource_id(),
        })
    }

    pub fn slots(&self) -> u32 {
        self.grid.iter().product()
    }

    /// Bytes uploaded so far.
    pub fn uploaded_bytes(&self) -> u64 {
        self.uploaded
    }

    /// Copies a brick's (B+4)³ data values into a slot. `variance` is the
    /// brick's variance placed on [0, 1] among the dataset's bricks (the
    /// prediction buffer's step, B10 §4.5).
    pub fn upload(&mut self, gpu: &Gpu, slot: u32, values: &[f32], variance: f32) {
        let s = self.side;
        assert_eq!(values.len(), (s * s * s) as usize, "brick size");
        assert!(slot < self.slots(), "slot {slot} out of the pool");
        let origin = wgpu::Origin3d {
            x: slot % self.grid[0] * s,
            y: slot / self.grid[0] % self.grid[1] * s,
            z: slot / (self.grid[0] * self.grid[1]) * s,
        };
        // No-data voxels (NaN) become the pool's no-data value: the top
        // code of an 8-bit slot (values take the 255 codes below it), or
        // NO_DATA_VALUE in a float pool. The kernel leaves them out of its
        // interpolation once the pool has any (`no_data`).
        let has_nan = values.iter().any(|v| v.is_nan());
        self.no_data |= has_nan;
        let (bytes, range): (Vec<u8>, [f32; 2]) = if self.float && !has_nan {
            (bytemuck::cast_slice(values).to_vec(), [0.0, 1.0])
        } else if self.float {
            let v: Vec<f32> = values
                .iter()
                .map(|&v| if v.is_nan() { NO_DATA_VALUE } else { v })
                .collect();
            (bytemuck::cast_slice(&v).to_vec(), [0.0, 1.0])
        } else {
            let (lo, hi) = crate::store::codec::value_range(values);
            let span = hi - lo;
            let top = if has_nan { 254.0 } else { 255.0 };
            let q = values
                .iter()
                .map(|&v| {
                    if v.is_nan() {
                        255
                    } else if span > 0.0 {
                        ((v - lo) / span * top).round().clamp(0.0, top) as u8
                    } else {
                        0
                    }
                })
                .collect();
            (q, [lo, span * 255.0 / top])
        };
        let bpp = if self.float { 4 } else { 1 };
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin,
                aspect: wgpu::TextureAspect::All,
            },
            &bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(s * bpp),
                rows_per_image: Some(s),
            },
            wgpu::Extent3d {
                width: s,
                height: s,
                depth_or_array_layers: s,
            },
        );
        let entry = [range[0], range[1], variance.clamp(0.0, 1.0), 0.0];
        gpu.queue
            .write_buffer(&self.ranges, slot as u64 * 16, bytemuck::cast_slice(&entry));
        self.uploaded += bytes.len() as u64;
    }
}
