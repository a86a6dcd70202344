//! Tool geometry over the volume images (G10 §5): the overlay's shapes
//! (`parallax_common::overlay`) rasterised by a wgpu render pass into one
//! layer per view (`shaders/overlay.wgsl`, its vertex stage projecting by
//! Eq. 1's rays), read back and laid over each view's image, so it shines
//! through the volume. Rays that miss the volume and tiles the culling drops
//! still show it: the geometry is drawn over the whole view.

use crate::gpu::Gpu;
use anyhow::Result;
use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use parallax_common::camera::View;
use parallax_common::overlay::{Overlay, Shape};

/// One vertex of `shaders/overlay.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Vertex {
    a: [f32; 4],
    b: [f32; 4],
    offset: [f32; 4],
    color: [f32; 4],
}

/// `OverlayView` of the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct GpuView {
    region: [f32; 4],
    eye: [f32; 4],
    observer: [f32; 4],
    size: [f32; 4],
    layout: [u32; 4],
}

/// Side of a cursor's dot (pixels).
const DOT: f32 = 5.0;

/// The triangles of `shapes` (two a segment, a dot and a glyph pixel).
/// A label is text in space: the 8×8 glyphs of `font8x8`, `label_height`
/// metres tall, in the plane parallel to the screen through its anchor,
/// half a height up and right of it, so that in a light field view every
/// eye reads it at the same place.
fn vertices(shapes: &[Shape], color: [f32; 4], label_height: f64) -> Vec<Vertex> {
    let mut out = Vec::new();
    let p = |x: DVec3, w: f32| [x.x as f32, x.y as f32, x.z as f32, w];
    let quad = |out: &mut Vec<Vertex>, at: DVec3, x0: f32, y0: f32, x1: f32, y1: f32| {
        for [ox, oy] in [[x0, y0], [x1, y0], [x1, y1], [x0, y0], [x1, y1], [x0, y1]] {
            out.push(Vertex {
                a: p(at, 0.0),
                b: p(at, 0.0),
                offset: [ox, oy, 0.0, 0.0],
                color,
            });
        }
    };
    for s in shapes {
        match s {
            Shape::Polyline(pts) => {
                for w in pts.windows(2) {
                    let (a, b) = (w[0], w[1]);
                    for (along, side) in [
                        (0.0, -1.0),
                        (1.0, -1.0),
                        (1.0, 1.0),
                        (0.0, -1.0),
                        (1.0, 1.0),
                        (0.0, 1.0),
                    ] {
                        out.push(Vertex {
                            a: p(a, along),
                            b: p(b, side),
                            offset: [0.0; 4],
                            color,
                        });
                    }
                }
            }
            Shape::Dot(at) => {
                let h = DOT / 2.0;
                quad(&mut out, *at, -h, -h, h, h);
            }
            Shape::Label(at, text) => {
                let g = label_height / 8.0;
                let origin = *at + DVec3::new(0.5, 0.5, 0.0) * label_height;
                for (k, ch) in text.chars().enumerate() {
                    let glyph = font8x8::legacy::BASIC_LEGACY
                        .get(ch as usize)
                        .copied()
                        .unwrap_or([0; 8]);
                    for (row, bits) in glyph.iter().enumerate() {
                        for col in 0..8 {
                            if bits & (1 << col) == 0 {
                                continue;
                            }
                            // Row 0 is the glyph's top.
                            let x = (k * 8 + col) as f64 * g;
                            let y = (7 - row) as f64 * g;
                            let corner =
                                |dx: f64, dy: f64| origin + DVec3::new(x + dx, y + dy, 0.0);
                            for c in [
                                corner(0.0, 0.0),
                                corner(g, 0.0),
                                corner(g, g),
                                corner(0.0, 0.0),
                                corner(g, g),
                                corner(0.0, g),
                            ] {
                                out.push(Vertex {
                                    a: p(c, 0.0),
                                    b: p(c, 0.0),
                                    offset: [0.0; 4],
                                    color,
                                });
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// The overlay's pipeline, and its layers' texture while views keep their
/// sizes.
pub struct OverlayRenderer {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    target: Option<([u32; 3], wgpu::Texture)>,
    /// The views, the vertices and the read-back, kept from frame to frame
    /// (grown to the next power of two when a frame needs more).
    views: Option<wgpu::Buffer>,
    vertices: Option<wgpu::Buffer>,
    staging: Option<wgpu::Buffer>,
    /// Bound where a frame has no depths to combine with.
    no_depth: wgpu::Buffer,
}

/// `slot`'s buffer, made anew (at the next power of two of `size`) only
/// where it is missing or smaller than `size`.
fn kept<'a>(
    dev: &wgpu::Device,
    slot: &'a mut Option<wgpu::Buffer>,
    size: u64,
    usage: wgpu::BufferUsages,
    label: &'static str,
) -> &'a wgpu::Buffer {
    if slot.as_ref().is_none_or(|b| b.size() < size) {
        *slot = Some(dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.next_power_of_two().max(256),
            usage,
            mapped_at_creation: false,
        }));
    }
    slot.as_ref().expect("made above")
}

const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

impl OverlayRenderer {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        let dev = &gpu.device;
        let module = gpu.validated("shaders/overlay.wgsl", || {
            dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("overlay.wgsl"),
                source: wgpu::ShaderSource::Wgsl(include_str!("../../shaders/overlay.wgsl").into()),
            })
        })?;
        let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("overlay"),
            entries: &[0, 1].map(|binding| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }),
        });
        let pl = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("overlay"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x4, 1 => Float32x4, 2 => Float32x4, 3 => Float32x4];
        let pipeline = gpu.validated("the overlay pipeline", || {
            dev.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("overlay"),
                layout: Some(&pl),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<Vertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &attributes,
                    })],
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: FORMAT,
                        blend: Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                multiview_mask: None,
                cache: None,
            })
        })?;
        let no_depth = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("overlay: no depth"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        Ok(OverlayRenderer {
            pipeline,
            layout,
            target: None,
            views: None,
            vertices: None,
            staging: None,
            no_depth,
        })
    }

    /// Each view's overlay layer: premultiplied RGBA, 8 bits, rows from
    /// the top (empty layers where there is nothing to draw). `depth`: the
    /// frame's recorded depths for depth combination, with the volume's
    /// units per metre.
    pub fn draw(
        &mut self,
        gpu: &Gpu,
        shapes: &[Shape],
        overlay: &Overlay,
        views: &[View],
        depth: Option<(&wgpu::Buffer, f64)>,
    ) -> Result<Vec<Vec<[u8; 4]>>> {
        let color = overlay.color.map(|c| c as f32);
        let verts = vertices(shapes, color, overlay.label_height);
        if verts.is_empty() || views.is_empty() {
            return Ok(views
                .iter()
                .map(|v| vec![[0; 4]; (v.resolution[0] * v.resolution[1]) as usize])
                .collect());
        }
        let dev = &gpu.device;
        let w = views.iter().map(|v| v.resolution[0]).max().unwrap_or(1);
        let h = views.iter().map(|v| v.resolution[1]).max().unwrap_or(1);
        let dims = [w, h, views.len() as u32];
        if self.target.as_ref().map(|(d, _)| *d) != Some(dims) {
            let tex = dev.create_texture(&wgpu::TextureDescriptor {
                label: Some("overlay layers"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: dims[2],
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            self.target = Some((dims, tex));
        }
        let tex = &self.target.as_ref().expect("made above").1;
        let mut first = 0u32;
        let gv: Vec<GpuView> = views
            .iter()
            .map(|v| {
                let f = |x: f64| x as f32;
                let layout = [first, depth.is_some() as u32, 0, 0];
                first += v.resolution[0] * v.resolution[1];
                GpuView {
                    region: v.region.map(f),
                    eye: [f(v.eye[0]), f(v.eye[1]), f(v.eye[2]), f(v.eta)],
                    observer: [f(v.observer[0]), f(v.observer[1]), f(v.observer[2]), 0.0],
                    size: [
                        v.resolution[0] as f32,
                        v.resolution[1] as f32,
                        overlay.line_width as f32,
                        depth.map_or(0.0, |(_, k)| k as f32),
                    ],
                    layout,
                }
            })
            .collect();
        let gv_bytes: &[u8] = bytemuck::cast_slice(&gv);
        let vert_bytes: &[u8] = bytemuck::cast_slice(&verts);
        let written = |slot: &'_ mut Option<wgpu::Buffer>, bytes: &[u8], usage, label| {
            let b = kept(
                dev,
                slot,
                bytes.len() as u64,
                usage | wgpu::BufferUsages::COPY_DST,
                label,
            );
            gpu.queue.write_buffer(b, 0, bytes);
            b.clone()
        };
        let view_buf = written(
            &mut self.views,
            gv_bytes,
            wgpu::BufferUsages::STORAGE,
            "overlay views",
        );
        let vert_buf = written(
            &mut self.vertices,
            vert_bytes,
            wgpu::BufferUsages::VERTEX,
            "overlay vertices",
        );
        let bind = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("overlay"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: view_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: depth.map_or(&self.no_depth, |(b, _)| b).as_entire_binding(),
                },
            ],
        });
        let row = (w * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let layer_bytes = row as u64 * h as u64;
        let read_bytes = layer_bytes * views.len() as u64;
        let staging = kept(
            dev,
            &mut self.staging,
            read_bytes,
            wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            "overlay read-back",
        );
        let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("overlay"),
        });
        for (i, v) in views.iter().enumerate() {
            let layer = tex.create_view(&wgpu::TextureViewDescriptor {
                label: Some("overlay layer"),
                dimension: Some(wgpu::TextureViewDimension::D2),
                base_array_layer: i as u32,
                array_layer_count: Some(1),
                ..Default::default()
            });
            {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("overlay"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &layer,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    ..Default::default()
                });
                let [vw, vh] = v.resolution;
                pass.set_viewport(0.0, 0.0, vw as f32, vh as f32, 0.0, 1.0);
                pass.set_scissor_rect(0, 0, vw, vh);
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.set_vertex_buffer(0, vert_buf.slice(..vert_bytes.len() as u64));
                pass.draw(0..verts.len() as u32, i as u32..i as u32 + 1);
            }
            enc.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture: tex,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: i as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: staging,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: layer_bytes * i as u64,
                        bytes_per_row: Some(row),
                        rows_per_image: Some(h),
                    },
                },
                wgpu::Extent3d {
                    width: v.resolution[0],
                    height: v.resolution[1],
                    depth_or_array_layers: 1,
                },
            );
        }
        gpu.queue.submit([enc.finish()]);
        let out = {
            let data = gpu.map_read(staging.slice(..read_bytes), "the overlay layers")?;
            views
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    let [vw, vh] = v.resolution;
                    let mut px = Vec::with_capacity((vw * vh) as usize);
                    for y in 0..vh as u64 {
                        let start = (layer_bytes * i as u64 + y * row as u64) as usize;
                        let line = &data[start..start + 4 * vw as usize];
                        px.extend(line.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
                    }
                    px
                })
                .collect()
        };
        staging.unmap();
        Ok(out)
    }
}

/// Lays `layer` (premultiplied, 8 bits) over `image` (premultiplied, f32):
/// the geometry in front of the volume.
pub fn lay_over(image: &mut [[f32; 4]], layer: &[[u8; 4]]) {
    for (p, o) in image.iter_mut().zip(layer) {
        if o[3] == 0 {
            continue;
        }
        let o = o.map(|c| c as f32 / 255.0);
        let keep = 1.0 - o[3];
        for c in 0..4 {
            p[c] = (o[c] + p[c] * keep).min(1.0);
        }
    }
}
