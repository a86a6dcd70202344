//! The GPU brick pool (G08 §4, G10 §5): one 3D texture cut into slots of
//! (B+4)³ texels, plus each slot's value range. 8-bit pools store each brick
//! quantised against its own range (G10 §5) in `r8unorm`; full-precision
//! pools store data values in `r32float`.

use crate::gpu::Gpu;
use anyhow::{bail, Result};

/// What a no-data voxel is in a float pool (the kernel's `NO_DATA_TAP`
/// threshold is 1e38 there).
pub const NO_DATA_VALUE: f32 = 3.0e38;

/// Bits of one slot's empty-macrocell mask: up to 8³ cells.
pub const CELL_WORDS: u32 = 16;

/// Texels of one slot's entry in the slot table (WGSL `slot_range`,
/// `cell_empty`, `layer_ranges`): its range (a vec4 of f32 bits), its cell
/// bits, four words a texel, then the registered layers' ranges (two
/// texels, used by layered pools only).
pub const SLOT_TEXELS: u64 = 1 + CELL_WORDS as u64 / 4 + 2;

/// Empty-space skipping inside bricks (L12 §4.1): each slot's B³ core is
/// cut into C³ macrocells of M³ voxels, and each cell keeps the value range
/// of the voxels that interpolation anywhere inside it reads (its voxels
/// and one more on every side). A cell whose range the transfer function
/// maps to τ ≡ 0 (the emptiness table: exact at bin granularity,
/// conservative) is empty; the kernel steps over it. Every segment it skips
/// would have added exactly nothing (both ends' values lie in the range, so
/// the pre-integrated segment is zero), and the samples after it fall where
/// they would have: the image does not change.
///
/// The ranges come with the brick from the database (format 4, computed by
/// the importer: `store::cells`); for older files, from the decoded brick at
/// upload (one pass over its values).
pub struct Macrocells {
    /// Cells per axis C (0: bricks whose side no cell size divides; none).
    pub per_axis: u32,
    /// Voxels per cell side M.
    pub voxels: u32,
    /// Per slot, C³ (lo, hi) data-value ranges (lo > hi: the cell has no
    /// data at all), per channel of a layered pool (cell-major).
    ranges: Vec<[f32; 2]>,
    /// Values per texel (registered layers: one per medium).
    channels: usize,
    /// Per slot, the channels that hold data (bit k: channel k).
    masks: Vec<u32>,
    /// Per slot, [`CELL_WORDS`] words of empty bits.
    bits: Vec<u32>,
    /// Slots whose bits changed since the last flush, or all of them.
    dirty: Vec<u32>,
    all_dirty: bool,
}

impl Macrocells {
    /// Whether cell `k` (x + C·(y + C·z)) of `slot` is empty under the
    /// transfer function it was last marked with.
    pub fn is_empty(&self, slot: u32, k: usize) -> bool {
        let w = self.bits[slot as usize * CELL_WORDS as usize + k / 32];
        (w >> (k % 32)) & 1 == 1
    }

    /// Cells for `slots` slots of bricks of side `b`, cell k of slot s
    /// empty where `empty(s, k)` (tests of what reads them).
    #[cfg(test)]
    pub(crate) fn with_empty(
        slots: u32,
        b: u32,
        mut empty: impl FnMut(u32, usize) -> bool,
    ) -> Self {
        let (per_axis, voxels) = Self::layout(b);
        let n = (per_axis * per_axis * per_axis) as usize;
        let mut bits = vec![0u32; slots as usize * CELL_WORDS as usize];
        for s in 0..slots {
            for k in 0..n {
                if empty(s, k) {
                    bits[s as usize * CELL_WORDS as usize + k / 32] |= 1 << (k % 32);
                }
            }
        }
        Macrocells {
            per_axis,
            voxels,
            ranges: vec![[1.0, 0.0]; slots as usize * n],
            channels: 1,
            masks: vec![1; slots as usize],
            bits,
            dirty: Vec::new(),
            all_dirty: false,
        }
    }

    /// The cell size for bricks of side `b`: 4 voxels, doubled until at
    /// most 8 cells per axis; none when it does not divide `b`.
    pub fn layout(b: u32) -> (u32, u32) {
        let (c, m) = crate::store::cells::layout(b as usize);
        (c as u32, m as u32)
    }

    /// A brick's ranges as the database stores them.
    fn set_stored(&mut self, slot: u32, cells: &[[f32; 2]]) {
        let n = self.cells();
        self.ranges[slot as usize * n..(slot as usize + 1) * n].copy_from_slice(cells);
    }

    /// The ranges of channel `ch` of a layered slot (cell-major, channels
    /// interleaved).
    fn set_channel(&mut self, slot: u32, ch: usize, cells: &[[f32; 2]]) {
        let (n, c) = (self.cells(), self.channels);
        for (k, r) in cells.iter().enumerate() {
            self.ranges[(slot as usize * n + k) * c + ch] = *r;
        }
    }

    fn cells(&self) -> usize {
        (self.per_axis * self.per_axis * self.per_axis) as usize
    }

    /// The ranges of one uploaded brick, from the (B+4)³ values the kernel
    /// interpolates (`value(i)`: the data value of stored voxel i, None
    /// for no data), as the importer computes them (`store::cells`).
    fn set_ranges(&mut self, slot: u32, side: u32, value: impl Fn(usize) -> Option<f64>) {
        let b = side as usize - 2 * crate::store::OVERLAP;
        self.set_stored(slot, &crate::store::cells::ranges(b, value));
    }

    /// Marks the empty cells of `slot` under `empty(channel, lo, hi)`: in
    /// a layered slot a cell is empty where every channel with data is.
    fn mark(&mut self, slot: u32, empty: &dyn Fn(usize, f64, f64) -> bool) {
        let (n, c) = (self.cells(), self.channels);
        let mask = self.masks[slot as usize];
        let words =
            &mut self.bits[(slot * CELL_WORDS) as usize..((slot + 1) * CELL_WORDS) as usize];
        words.fill(0);
        for (i, cell) in self.ranges[slot as usize * n * c..(slot as usize + 1) * n * c]
            .chunks_exact(c)
            .enumerate()
        {
            let all = cell.iter().enumerate().all(|(ch, r)| {
                let [lo, hi] = r.map(f64::from);
                // Widened by a little more than the kernel's f32 rounding
                // of its values: never empty where a sample could fall
                // outside.
                let pad = 1e-5 * (lo.abs().max(hi.abs()) + (hi - lo).abs()) + f64::MIN_POSITIVE;
                (mask >> ch) & 1 == 0 || lo > hi || empty(ch, lo - pad, hi + pad)
            });
            if all {
                words[i / 32] |= 1 << (i % 32);
            }
        }
        if !self.all_dirty {
            self.dirty.push(slot);
        }
    }
}

pub struct BrickPool {
    pub(crate) texture: wgpu::Texture,
    pub(crate) view: wgpu::TextureView,
    pub(crate) slots: super::texels::TexelTable,
    /// Empty-space skipping inside bricks.
    pub cells: Macrocells,
    /// Slots that hold a brick.
    filled: Vec<bool>,
    /// Per slot, the data values its texels map to: min, max − min (the
    /// kernel reads them with the index node, `frame_table`).
    pub(crate) values: Vec<[f32; 2]>,
    /// Slots along x, y, z.
    pub grid: [u32; 3],
    /// Texels per side of a slot.
    pub side: u32,
    /// Full precision (`r32float`) or 8 bit (`r8unorm`).
    pub float: bool,
    /// Values per texel: 1, or with registered layers the scene volume's
    /// and each layer's (`rg32float`, `rgba32float`; the kernel's LAYERS).
    pub channels: u32,
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
        Self::layered_slot_bytes(side, float, 1)
    }

    /// Bytes one slot of `channels` values per texel takes.
    pub fn layered_slot_bytes(side: u32, float: bool, channels: u32) -> u64 {
        let texel = channels as u64 * if float { 4 } else { 1 };
        side as u64 * side as u64 * side as u64 * texel
    }

    /// The most slots a byte budget buys.
    pub fn slots_for_budget(budget_bytes: u64, side: u32, float: bool) -> u32 {
        Self::layered_slots_for_budget(budget_bytes, side, float, 1)
    }

    /// The most slots of `channels` values per texel a byte budget buys.
    pub fn layered_slots_for_budget(
        budget_bytes: u64,
        side: u32,
        float: bool,
        channels: u32,
    ) -> u32 {
        (budget_bytes / Self::layered_slot_bytes(side, float, channels)).min(u32::MAX as u64) as u32
    }

    /// Values per texel of a pool for a scene volume and `layers`
    /// registered layers (texture formats have 1, 2 or 4 channels).
    pub fn channels_for(layers: usize) -> u32 {
        match layers {
            0 => 1,
            1 => 2,
            _ => 4,
        }
    }

    pub fn new(gpu: &Gpu, slots: u32, side: u32, float: bool) -> Result<Self> {
        Self::with_channels(gpu, slots, side, float, 1)
    }

    /// A pool of `channels` values per texel (the scene volume's in the
    /// first and its layers' in the others), f32 or 8-bit codes against
    /// each brick's own range per channel.
    pub fn with_channels(
        gpu: &Gpu,
        slots: u32,
        side: u32,
        float: bool,
        channels: u32,
    ) -> Result<Self> {
        if slots == 0 {
            bail!(
                "the GPU brick pool budget is too small for even one brick ({} KiB per brick)",
                Self::layered_slot_bytes(side, float, channels) / 1024
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
        let format = match (float, channels) {
            (true, 2) => wgpu::TextureFormat::Rg32Float,
            (true, 4) => wgpu::TextureFormat::Rgba32Float,
            (true, _) => wgpu::TextureFormat::R32Float,
            (false, 2) => wgpu::TextureFormat::Rg8Unorm,
            (false, 4) => wgpu::TextureFormat::Rgba8Unorm,
            (false, _) => wgpu::TextureFormat::R8Unorm,
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
        // Per slot (the kernel's `Slot`): its value range (16 bytes), then
        // its empty-macrocell bits.
        let slots = super::texels::TexelTable::new(
            gpu,
            "brick ranges and macrocells",
            grid.iter().product::<u32>() as u64 * SLOT_TEXELS,
        );
        let total = grid.iter().product::<u32>();
        let (per_axis, voxels) = Macrocells::layout(side.saturating_sub(4));
        let cells = Macrocells {
            per_axis,
            voxels,
            ranges: vec![
                [1.0, 0.0];
                total as usize * (per_axis as usize).pow(3) * channels as usize
            ],
            channels: channels as usize,
            masks: vec![1; total as usize],
            bits: vec![0; (total * CELL_WORDS) as usize],
            dirty: Vec::new(),
            all_dirty: false,
        };
        Ok(BrickPool {
            texture,
            view,
            slots,
            cells,
            filled: vec![false; total as usize],
            values: vec![[0.0; 2]; total as usize],
            grid,
            side,
            float,
            channels,
            no_data: false,
            uploaded: 0,
            id: super::next_resource_id(),
        })
    }

    pub fn slots(&self) -> u32 {
        self.grid.iter().product()
    }

    /// Marks the empty macrocells of `slot` (just uploaded) under the
    /// transfer function's emptiness test.
    pub fn mark_cells(&mut self, slot: u32, empty: &dyn Fn(usize, f64, f64) -> bool) {
        if self.cells.per_axis > 0 {
            self.cells.mark(slot, empty);
        }
    }

    /// Marks every filled slot's empty macrocells anew (a new transfer
    /// function).
    pub fn mark_all_cells(&mut self, empty: &dyn Fn(usize, f64, f64) -> bool) {
        if self.cells.per_axis == 0 {
            return;
        }
        self.cells.all_dirty = true;
        self.cells.dirty.clear();
        for slot in 0..self.slots() {
            if self.filled[slot as usize] {
                self.cells.mark(slot, empty);
            }
        }
    }

    /// Sends changed empty-cell bits to the GPU.
    pub fn flush_cells(&mut self, gpu: &Gpu) {
        let c = &mut self.cells;
        if std::mem::take(&mut c.all_dirty) {
            c.dirty = (0..self.filled.len() as u32)
                .filter(|&s| self.filled[s as usize])
                .collect();
        }
        // Only the slots just marked: bricks stream in a few a frame.
        c.dirty.sort_unstable();
        c.dirty.dedup();
        let w = CELL_WORDS as usize;
        for &slot in &c.dirty {
            let words = &c.bits[slot as usize * w..(slot as usize + 1) * w];
            self.slots.write(
                gpu,
                slot as u64 * SLOT_TEXELS + 1,
                bytemuck::cast_slice(words),
            );
        }
        c.dirty.clear();
    }

    /// Bytes uploaded so far.
    pub fn uploaded_bytes(&self) -> u64 {
        self.uploaded
    }

    /// Copies a node's bricks of the scene volume and its registered layers
    /// ([`crate::store::LayerBricks`]) into a slot, one channel each (zeros
    /// where a medium has none; a no-data voxel takes `fills`' value of its
    /// channel): f32, or 8-bit codes against each channel's own range, the
    /// volume's in the slot's range, the layers' in the slot's last two
    /// texels (`layer_ranges`). The mask of the channels that hold data
    /// goes in the range's fourth word (the kernel composites only those),
    /// and each channel's macrocell ranges are kept (a cell is empty where
    /// every medium with data is).
    pub fn upload_layered(
        &mut self,
        gpu: &Gpu,
        slot: u32,
        brick: &crate::store::Brick,
        fills: &[f32],
        variance: f32,
    ) {
        let s = self.side;
        let n = (s * s * s) as usize;
        let c = self.channels as usize;
        assert_eq!(brick.values.len(), n, "brick size");
        assert!(slot < self.slots(), "slot {slot} out of the pool");
        let lb = brick
            .layered
            .as_ref()
            .expect("a layered pool takes layered bricks");
        let media: Vec<Option<Vec<f32>>> = std::iter::once(lb.main.then_some(&brick.values))
            .chain(lb.layers.iter().map(Option::as_ref))
            .enumerate()
            .map(|(k, v)| {
                v.map(|v| {
                    v.iter()
                        .map(|&x| if x.is_nan() { fills[k] } else { x })
                        .collect()
                })
            })
            .collect();
        // Each channel's range (value = lo + span · stored) and the values
        // the kernel interpolates.
        let mut ranges = [[0.0f32, 1.0]; 4];
        let mut decoded: Vec<Option<Vec<f32>>> = vec![None; c];
        let bytes: Vec<u8> = if self.float {
            let mut texels = vec![0f32; n * c];
            for (k, m) in media.iter().enumerate() {
                if let Some(v) = m {
                    for (t, &x) in texels.chunks_exact_mut(c).zip(v) {
                        t[k] = x;
                    }
                }
            }
            // A placed layer's voxels without medium (its NO_LAYER,
            // below −1e20) take no part in a cell's range, as NaN does not.
            for (k, m) in media.into_iter().enumerate() {
                decoded[k] = m.map(|v| {
                    v.into_iter()
                        .map(|x| if x < -1e20 { f32::NAN } else { x })
                        .collect()
                });
            }
            bytemuck::cast_slice(&texels).to_vec()
        } else {
            let mut codes = vec![0u8; n * c];
            for (k, m) in media.iter().enumerate() {
                if let Some(v) = m {
                    let (q, r) = quantise(v, false);
                    for (t, &x) in codes.chunks_exact_mut(c).zip(&q) {
                        t[k] = x;
                    }
                    let scale = r[1] / 255.0;
                    decoded[k] = Some(q.iter().map(|&x| r[0] + scale * x as f32).collect());
                    ranges[k] = r;
                }
            }
            codes
        };
        let bpp = c as u32 * if self.float { 4 } else { 1 };
        self.write_slot(gpu, slot, &bytes, bpp);
        let mask = lb.mask();
        if self.cells.per_axis > 0 {
            self.cells.masks[slot as usize] = mask;
            let b = s as usize - 2 * crate::store::OVERLAP;
            let none = vec![[1.0f32, 0.0]; self.cells.cells()];
            for (k, d) in decoded.iter().enumerate() {
                let cells = match d {
                    Some(v) => crate::store::cells::ranges_of(b, v),
                    None => none.clone(),
                };
                self.cells.set_channel(slot, k, &cells);
            }
        }
        self.filled[slot as usize] = true;
        self.values[slot as usize] = ranges[0];
        let [lo, span, var] =
            [ranges[0][0], ranges[0][1], variance.clamp(0.0, 1.0)].map(f32::to_bits);
        let r = |k: usize| ranges[k].map(f32::to_bits);
        let (r1, r2, r3) = (r(1), r(2), r(3));
        self.slots
            .write(gpu, slot as u64 * SLOT_TEXELS, &[[lo, span, var, mask]]);
        self.slots.write(
            gpu,
            slot as u64 * SLOT_TEXELS + SLOT_TEXELS - 2,
            &[[r1[0], r1[1], r2[0], r2[1]], [r3[0], r3[1], 0, 0]],
        );
        self.uploaded += bytes.len() as u64;
    }

    /// Writes one slot's (B+4)³ texels of `bpp` bytes.
    fn write_slot(&self, gpu: &Gpu, slot: u32, bytes: &[u8], bpp: u32) {
        let s = self.side;
        let origin = wgpu::Origin3d {
            x: slot % self.grid[0] * s,
            y: slot / self.grid[0] % self.grid[1] * s,
            z: slot / (self.grid[0] * self.grid[1]) * s,
        };
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin,
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
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
    }

    /// Copies a brick's (B+4)³ data values into a slot. `variance` is the
    /// brick's variance placed on [0, 1] among the dataset's bricks (the
    /// prediction buffer's step, B10 §4.5). `cells`: the brick's macrocell
    /// ranges as stored (format 4), else they are computed from `values`.
    pub fn upload(
        &mut self,
        gpu: &Gpu,
        slot: u32,
        values: &[f32],
        cells: Option<&[[f32; 2]]>,
        variance: f32,
    ) {
        let s = self.side;
        assert_eq!(values.len(), (s * s * s) as usize, "brick size");
        assert!(slot < self.slots(), "slot {slot} out of the pool");
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
            quantise(values, has_nan)
        };
        let bpp = if self.float { 4 } else { 1 };
        self.write_slot(gpu, slot, &bytes, bpp);
        let n_cells = self.cells.cells();
        if let Some(stored) = cells.filter(|c| n_cells > 0 && c.len() == n_cells) {
            self.cells.set_stored(slot, stored);
        } else if self.cells.per_axis > 0 {
            if self.float {
                self.cells.set_ranges(slot, s, |i| {
                    let v = values[i];
                    (!v.is_nan()).then_some(v as f64)
                });
            } else {
                let (lo, scale) = (range[0] as f64, range[1] as f64 / 255.0);
                let nan = has_nan;
                self.cells.set_ranges(slot, s, |i| {
                    let q = bytes[i];
                    (!(nan && q == 255)).then_some(lo + scale * q as f64)
                });
            }
        }
        self.filled[slot as usize] = true;
        self.values[slot as usize] = [range[0], range[1]];
        let entry = [range[0], range[1], variance.clamp(0.0, 1.0), 0.0].map(f32::to_bits);
        self.slots.write(gpu, slot as u64 * SLOT_TEXELS, &[entry]);
        self.uploaded += bytes.len() as u64;
    }
}

/// A brick's values as 8-bit codes against its own range (G10 §5), and the
/// range the kernel decodes them with (value = range.0 + range.1 · code /
/// 255). No-data voxels (NaN) take the top code, the values the 255 below.
fn quantise(values: &[f32], has_nan: bool) -> (Vec<u8>, [f32; 2]) {
    let (lo, hi) = crate::store::codec::value_range(values);
    // Integer bricks spanning at most the codes go on a grid of
    // 1/2^k (code = (value − lo)·2^k, the finest that fits),
    // losslessly, as the store does; the texture unit's filtered
    // values then keep the finest steps the codes allow.
    let unit = crate::store::codec::unit_step_fits(
        values,
        lo,
        hi,
        crate::store::BrickEncoding::U8Range,
        has_nan,
    );
    let top = if has_nan { 254.0 } else { 255.0 };
    let span = if unit {
        let mut grid = 1.0;
        while (hi - lo) * grid * 2.0 <= top && grid < 128.0 {
            grid *= 2.0;
        }
        top / grid
    } else {
        hi - lo
    };
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
}
