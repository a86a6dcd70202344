//! The transfer function's tables on the GPU: the pre-integration table
//! (G10 §4 Eq. 2) with its running integral, the optional 2D table and the
//! closed form's pieces.

use super::{next_resource_id, texels};
use crate::gpu::Gpu;
use parallax_common::config::Preintegration;
use parallax_common::tf::closed::{ClosedForm, GpuPieces, MAX_PIECES};
use parallax_common::tf::{Channel, PreintLayout, PreintTable, TransferFunction};
use wgpu::util::DeviceExt;

/// The pre-integration table on the GPU (G10 §4 Eq. 2).
///
/// Segment integrals over whole bins come from the dyadic sum pyramid
/// (every term ≥ 0, nothing cancels). When the transfer function's dynamic
/// range allows it, a running integral F_j stored as an f32 pair (hi + lo,
/// ≈ 48 significant bits) is added: one difference instead of up to
/// 2·log2 N pyramid reads. Its error, ≈ 2⁻⁴⁸·F_total, is then below 2⁻²⁸ of
/// the smallest non-zero bin — the cancellation G10's single running
/// integral suffers cannot reach a visible size. Extreme ranges (say
/// τ = 1e-6 beside 1e6) keep the pyramid alone.
pub struct TfTable {
    /// The table's entries (WGSL `tf_entry`).
    pub(super) buffer: texels::TexelTable,
    pub(super) layout: PreintLayout,
    /// Index (in vec4 entries) of the F_j pairs, 0 when not used.
    pub(super) prefix_offset: u32,
    /// First entry of the (ι, ν, 0, 0) part and its running integral's.
    pub(super) aux_base: u32,
    pub(super) aux_prefix: u32,
    /// ι_max of the transfer function (MImDA's termination estimate).
    pub(super) max_importance: f32,
    /// The largest extinction of the volume's function (whether a segment
    /// can be optically thick: `Raycaster::kernel`).
    pub(super) max_extinction: f32,
    /// Whether the march pre-integrates from the segments' ends
    /// (preint.wgsl `end_average`), and whether the table allows it: a
    /// running integral, and bin integrals within [`END_RANGE`] of each
    /// other in every DVR channel.
    pub(super) end_path: bool,
    pub(super) end_allowed: bool,
    /// The 2D table (`preintegration = "2d"`), made when first asked for,
    /// and its nodes per axis.
    pub(super) grid: Option<(wgpu::Texture, wgpu::TextureView, u32)>,
    /// How many pieces the DVR channels' closed form has
    /// (`preintegration = "analytic"`), where the function has one, and the
    /// uniform the kernel reads them from (zeros without).
    pub(super) closed_pieces: Option<u32>,
    pub(super) pieces: wgpu::Buffer,
    /// Which table this is (a bind group names one table).
    pub(super) id: u64,
    /// The registered layers' DVR tables, after the volume's parts: each
    /// one's `LayerParams` table and entry fields (its opacity and view
    /// opacity are the frame's).
    pub(super) layers: Vec<super::params::LayerParams>,
    /// Every layer's table allows the end path (as `end_allowed`).
    layers_end: bool,
}

/// An n × n rgba32float texture for the 2D pre-integration table.
pub(super) fn grid_descriptor(label: &str, n: u32) -> wgpu::TextureDescriptor<'_> {
    wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: n,
            height: n,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    }
}

/// Largest F_total / (smallest non-zero bin) for which the running integral
/// is used.
const PREFIX_RANGE: f64 = (1u64 << 20) as f64;

/// Largest (largest bin integral) / (smallest non-zero one) of a channel for
/// which the march pre-integrates from the segments' ends: its f32 partial
/// bins then err by at most 2⁻²³·2¹² = 2⁻¹¹ of the smallest non-zero bin.
const END_RANGE: f64 = (1u64 << 12) as f64;

/// `x` / (smallest non-zero bin integral of a channel); 1 where `x` is 0.
fn over_smallest_bin(bins: &[f64], x: f64) -> f64 {
    let min = bins
        .iter()
        .cloned()
        .filter(|&x| x > 0.0)
        .fold(f64::INFINITY, f64::min);
    if x > 0.0 {
        x / min
    } else {
        1.0
    }
}

/// Whether every DVR channel's bin integrals lie within [`END_RANGE`] of
/// each other (f32 partial bins keep their precision).
fn dvr_within_end_range(table: &PreintTable) -> bool {
    [
        Channel::Tau,
        Channel::EmissionR,
        Channel::EmissionG,
        Channel::EmissionB,
    ]
    .iter()
    .all(|&ch| {
        let bins = table.level(ch, 0);
        over_smallest_bin(bins, bins.iter().cloned().fold(0.0, f64::max)) <= END_RANGE
    })
}

/// Where a table's parts went in the table texture (`push_parts`).
struct Parts {
    layout: PreintLayout,
    base: u32,
    prefix: u32,
    aux: u32,
    aux_prefix: u32,
}

impl TfTable {
    /// The tables of `tf`, `table` its pre-integration table.
    pub fn new(gpu: &Gpu, table: &PreintTable, tf: &TransferFunction) -> Self {
        Self::with_layers(gpu, table, tf, &[])
    }

    /// The tables of `tf` and, after them, the DVR tables of registered
    /// layers (shaders/shared/layers.wgsl), each with its running integral
    /// where its range allows.
    pub fn with_layers(
        gpu: &Gpu,
        table: &PreintTable,
        tf: &TransferFunction,
        layers: &[(&PreintTable, f64)],
    ) -> Self {
        // MImDA's termination needs the largest importance of every medium.
        let max_importance = layers
            .iter()
            .map(|l| l.1)
            .fold(tf.max_importance(), f64::max);
        // Two interleaved parts with the same layout: (τ, k̃r, k̃g, k̃b), what
        // DVR reads, one 16-byte load per table entry; then (ι, ν, 0, 0),
        // read only by the MImDA and refraction kernels. The same for each
        // layer after the volume's.
        let mut data = Vec::new();
        let vol = Self::push_parts(&mut data, table);
        let (layout, prefix_offset, aux_base, aux_prefix) =
            (vol.layout, vol.prefix, vol.aux, vol.aux_prefix);
        let mut layer_params = Vec::with_capacity(layers.len());
        let mut layers_end = true;
        for &(t, _) in layers {
            let p = Self::push_parts(&mut data, t);
            let l = p.layout;
            layers_end &= p.prefix != 0 && dvr_within_end_range(t);
            layer_params.push(super::params::LayerParams {
                table: [
                    l.vmin as f32,
                    (1.0 / l.bin_width) as f32,
                    l.n_bins as f32,
                    0.0,
                ],
                at: [p.base, p.base + l.mid_offset, p.prefix, l.levels],
                aux: [p.aux, p.aux_prefix, 0, 0],
                ..Default::default()
            });
        }
        let texels: Vec<[u32; 4]> = data.iter().map(|v| v.map(f32::to_bits)).collect();
        let buffer = texels::TexelTable::new(gpu, "pre-integration table", texels.len() as u64);
        buffer.write(gpu, 0, &texels);
        let end_allowed = prefix_offset != 0 && dvr_within_end_range(table);
        let closed = ClosedForm::new(tf, table.vmin(), table.vmax());
        let words: GpuPieces = closed
            .as_ref()
            .map_or([[0.0; 4]; 1 + 4 * MAX_PIECES], |c| c.gpu());
        let pieces = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("transfer function pieces"),
                contents: bytemuck::cast_slice(&words),
                usage: wgpu::BufferUsages::STORAGE,
            });
        TfTable {
            buffer,
            layout,
            prefix_offset,
            end_path: end_allowed,
            end_allowed,
            grid: None,
            closed_pieces: closed.map(|c| c.pieces.len() as u32),
            pieces,
            aux_base,
            aux_prefix,
            max_importance: max_importance as f32,
            max_extinction: tf.max_extinction() as f32,
            id: next_resource_id(),
            layers: layer_params,
            layers_end,
        }
    }

    /// Appends a table's two parts, (τ, k̃) then (ι, ν): where each starts
    /// and its running integral (0: none).
    fn push_parts(data: &mut Vec<[f32; 4]>, table: &PreintTable) -> Parts {
        let (planar, layout) = table.gpu_layout();
        let base = data.len() as u32;
        let dvr = [
            Some(Channel::Tau),
            Some(Channel::EmissionR),
            Some(Channel::EmissionG),
            Some(Channel::EmissionB),
        ];
        let prefix = Self::push_part(data, &planar, &layout, table, dvr);
        let aux = data.len() as u32;
        let aux_channels = [
            Some(Channel::Importance),
            Some(Channel::Refraction),
            None,
            None,
        ];
        let aux_prefix = Self::push_part(data, &planar, &layout, table, aux_channels);
        Parts {
            layout,
            base,
            prefix,
            aux,
            aux_prefix,
        }
    }

    /// Appends one part (four channels interleaved, nodes and pyramid) and,
    /// where the channels' range allows, its running integral; returns the
    /// running integral's first entry (0: none).
    fn push_part(
        data: &mut Vec<[f32; 4]>,
        planar: &[f32],
        layout: &PreintLayout,
        table: &PreintTable,
        channels: [Option<Channel>; 4],
    ) -> u32 {
        let stride = layout.channel_stride as usize;
        data.extend((0..stride).map(|i| {
            std::array::from_fn(|c| channels[c].map_or(0.0, |ch| planar[ch.index() * stride + i]))
        }));
        let bins: Vec<&[f64]> = channels
            .iter()
            .map(|c| c.map_or(&[][..], |ch| table.level(ch, 0)))
            .collect();
        let n = table.level(Channel::Tau, 0).len();
        let range = bins
            .iter()
            .map(|b| over_smallest_bin(b, b.iter().sum()))
            .fold(1.0, f64::max);
        if range > PREFIX_RANGE {
            return 0;
        }
        let start = data.len() as u32;
        let mut f = [0f64; 4];
        for j in 0..=n {
            let hi: [f32; 4] = std::array::from_fn(|c| f[c] as f32);
            let lo: [f32; 4] = std::array::from_fn(|c| (f[c] - hi[c] as f64) as f32);
            data.push(hi);
            data.push(lo);
            if j < n {
                for c in 0..4 {
                    f[c] += bins[c].get(j).copied().unwrap_or(0.0);
                }
            }
        }
        start
    }

    /// Whether every registered layer's table allows pre-integrating from
    /// the segments' ends (the kernel's LAYER_END).
    pub fn layers_end_path(&self) -> bool {
        self.layers_end && !self.layers.is_empty()
    }

    /// Whether whole bins are summed by the running integral.
    pub fn uses_running_integral(&self) -> bool {
        self.prefix_offset != 0
    }

    /// Whether the march pre-integrates from the segments' ends (each
    /// sample reads its bin once) rather than per segment.
    pub fn uses_end_path(&self) -> bool {
        self.end_path
    }

    /// Makes the 2D pre-integration table (PreintTable::grid) of `table`,
    /// the table this was made from, on the GPU, once; `preintegration =
    /// "2d"` samples it bilinearly.
    pub fn build_grid(&mut self, gpu: &Gpu, table: &PreintTable) {
        if self.grid.is_some() {
            return;
        }
        let n = table.grid_nodes() as u32;
        let data = table.grid();
        let texture = gpu.device.create_texture_with_data(
            &gpu.queue,
            &grid_descriptor("2D pre-integration table", n),
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&data),
        );
        let view = texture.create_view(&Default::default());
        self.grid = Some((texture, view, n));
        // Bind groups made for this table lack the new texture.
        self.id = next_resource_id();
    }

    /// Whether the DVR channels have a closed form the kernel can use
    /// (`preintegration = "analytic"`; otherwise that falls back to "2d").
    pub fn has_closed_form(&self) -> bool {
        self.closed_pieces.is_some()
    }

    /// The closed form's pieces over the data range (`None`: it has none
    /// the kernel can use).
    pub fn closed_pieces(&self) -> Option<u32> {
        self.closed_pieces
    }

    /// Whether `preintegration` reads the 2D table ([`Self::build_grid`]):
    /// "2d", and "analytic" where the function has no closed form.
    pub fn wants_grid(&self, preintegration: Preintegration) -> bool {
        match preintegration {
            Preintegration::TwoD => true,
            Preintegration::Analytic => !self.has_closed_form(),
            Preintegration::Exact | Preintegration::Auto => false,
        }
    }

    /// Pre-integrates per segment even where the table allows the end path
    /// (`false`), or from the ends again where it allows it (`true`): the
    /// same integral by another sum, for comparisons.
    pub fn allow_end_path(&mut self, allow: bool) {
        self.end_path = allow && self.end_allowed;
    }
}
