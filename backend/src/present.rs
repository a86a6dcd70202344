//! Showing frames on the display's outputs (`--present`; G10 §5: "each
//! back-end process controls a frame-buffer portion"). A back end opens one
//! borderless window per output that shows its projectors — at the output's
//! place on the X screen (by RandR name) or at the display file's rect — and
//! presents every frame there through a wgpu surface of the GPU that renders
//! it, when the coordinator's swap lock says so ([`ToBackend::Present`]).
//!
//! The windows are made with XCB (x11rb) rather than a windowing toolkit:
//! they take no input, and a process may hold several back ends (the
//! embedded mode), each with windows of its own, where a toolkit allows one
//! event loop per process. Each projector's image is converted to sRGB
//! bytes exactly as its PNG is ([`crate::output::rgb8`]), so the screen
//! shows what the files hold.
//!
//! [`ToBackend::Present`]: parallax_common::protocol::ToBackend::Present

use crate::gpu::Gpu;
use anyhow::{bail, Context, Result};
use parallax_common::config::Display;
use parallax_common::present::{Place, PresentMode};
use std::num::NonZeroU32;
use std::ptr::NonNull;
use x11rb::connection::Connection;
use x11rb::protocol::randr::ConnectionExt as _;
use x11rb::protocol::xproto::{ConnectionExt as _, CreateWindowAux, WindowClass};
use x11rb::xcb_ffi::XCBConnection;

/// One output's window and what it shows.
struct OutputWindow {
    label: String,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// The surface's byte order: B, G, R, A (else R, G, B, A).
    bgra: bool,
    /// (index into this back end's images, [x, y] in the window, [w, h]).
    tiles: Vec<(usize, [u32; 2], [u32; 2])>,
    /// Drawing straight from the ray caster's image buffer, where the
    /// surface takes it (an 8-bit unorm format it can render to).
    blit: Option<Blit>,
}

/// The windows of one back end. The surfaces go before the connection they
/// were made on (fields drop in order).
pub struct Presenter {
    outputs: Vec<OutputWindow>,
    conn: XCBConnection,
}

/// A connection to `$DISPLAY`, tried for up to a second: a server that
/// has just started (or is busy) may refuse the first attempts.
fn connect() -> Result<(XCBConnection, usize)> {
    let mut tries = 0;
    loop {
        match XCBConnection::connect(None) {
            Ok(c) => return Ok(c),
            Err(e) if tries >= 10 => return Err(e.into()),
            Err(_) => {
                tries += 1;
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
        }
    }
}

/// The X display a back end would present on, for messages.
fn display_name() -> String {
    std::env::var("DISPLAY").unwrap_or_default()
}

impl Presenter {
    /// Opens the windows of the outputs that show this back end's
    /// projectors (`mine`: projector indices, in the order of its images).
    /// Errors name the output and the reason (the coordinator adds the
    /// rank).
    pub fn open(gpu: &Gpu, display: &Display, mine: &[usize]) -> Result<Self> {
        // The coordinator names the rank ("back end N failed to set up").
        let who = "--present";
        let x = display_name();
        if x.is_empty() {
            bail!("{who}: no X display to present on (DISPLAY is not set)");
        }
        let windows = match &display.looking_glass {
            // One window, the panel's: at the first output's place, or the
            // screen's corner; its one image is the panel.
            Some(lg) => vec![parallax_common::present::Window {
                label: "looking glass".into(),
                place: match display.present.outputs.first() {
                    Some(o) => match (&o.rect, &o.name) {
                        (Some(r), _) => {
                            Place::Rect([r[0] as i32, r[1] as i32], [r[2] as u32, r[3] as u32])
                        }
                        (None, Some(n)) => Place::Named(n.clone()),
                        (None, None) => Place::Rect([0, 0], lg.screen),
                    },
                    None => Place::Rect([0, 0], lg.screen),
                },
                tiles: vec![(display.projectors.len(), [0, 0])],
            }],
            None => display.windows("display")?,
        };
        let (conn, screen_num) =
            connect().with_context(|| format!("{who}: cannot open the X display '{x}'"))?;
        let root = conn.setup().roots[screen_num].clone();
        let mut res: Vec<[u32; 2]> = display.projectors.iter().map(|p| p.resolution).collect();
        // The panel stands as one more "projector", shown by this back end.
        let mut mine = mine.to_vec();
        if let Some(lg) = &display.looking_glass {
            res.push(lg.screen);
            mine = vec![res.len() - 1];
        }
        let mut outputs = Vec::new();
        for w in &windows {
            let ours: Vec<bool> = w.tiles.iter().map(|(p, _)| mine.contains(p)).collect();
            if !ours.contains(&true) {
                continue;
            }
            let what = format!("{who}: output '{}'", w.label);
            if ours.contains(&false) {
                bail!("{what}: shows projectors of several back ends; pin them to one with `rank` in their projector files");
            }
            let (pos, size) = match &w.place {
                Place::Rect(p, s) => (*p, *s),
                Place::Named(name) => named_output(&conn, root.root, name)
                    .with_context(|| format!("{what}: on the X display '{x}'"))?,
            };
            let [ew, eh] = w.extent(&res);
            if ew > size[0] || eh > size[1] {
                bail!(
                    "{what}: the projectors' images need {ew}×{eh} pixels, the output has {}×{}",
                    size[0],
                    size[1]
                );
            }
            let id = conn.generate_id()?;
            conn.create_window(
                x11rb::COPY_DEPTH_FROM_PARENT,
                id,
                root.root,
                pos[0] as i16,
                pos[1] as i16,
                size[0] as u16,
                size[1] as u16,
                0,
                WindowClass::INPUT_OUTPUT,
                x11rb::COPY_FROM_PARENT,
                &CreateWindowAux::new()
                    .override_redirect(1u32)
                    .background_pixel(root.black_pixel),
            )?;
            conn.map_window(id)?;
            conn.flush()?;
            let (surface, config, bgra) =
                surface(gpu, &conn, screen_num, id, size, display.present.mode)
                    .with_context(|| what.clone())?;
            let direct = config
                .usage
                .contains(wgpu::TextureUsages::RENDER_ATTACHMENT)
                && !config.format.is_srgb();
            let blit = match direct {
                true => Some(
                    Blit::new(gpu, config.format, w.tiles.len()).with_context(|| what.clone())?,
                ),
                false => None,
            };
            let tiles = w
                .tiles
                .iter()
                .map(|&(p, at)| {
                    let i = mine.iter().position(|&m| m == p).expect("checked above");
                    (i, at, res[p])
                })
                .collect();
            outputs.push(OutputWindow {
                label: w.label.clone(),
                surface,
                config,
                bgra,
                tiles,
                blit,
            });
        }
        Ok(Presenter { outputs, conn })
    }

    /// Windows opened.
    pub fn outputs(&self) -> usize {
        self.outputs.len()
    }

    /// Whether every output can draw straight from the ray caster's image
    /// buffer ([`Presenter::present_direct`]).
    pub fn direct(&self) -> bool {
        self.outputs.iter().all(|o| o.blit.is_some())
    }

    /// Presents the frame straight from the ray caster's image buffer on
    /// the device (no read-back): this back end's image `i` starts at
    /// pixel `first[i]` of `image`.
    pub fn present_direct(&mut self, gpu: &Gpu, image: &wgpu::Buffer, first: &[u64]) -> Result<()> {
        while self.conn.poll_for_event()?.is_some() {}
        for o in &mut self.outputs {
            let blit = o
                .blit
                .as_ref()
                .context("this output cannot draw from the device")?;
            let binds: Vec<wgpu::BindGroup> = o
                .tiles
                .iter()
                .zip(&blit.tiles)
                .map(|(&(i, [x0, y0], [w, _]), u)| {
                    let t = TileUniform {
                        offset: first[i] as u32,
                        width: w,
                        x0,
                        y0,
                    };
                    gpu.queue.write_buffer(u, 0, bytemuck::bytes_of(&t));
                    blit.bind(gpu, u, image)
                })
                .collect();
            let frame = acquire(gpu, o)?;
            let view = frame.texture.create_view(&Default::default());
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("present"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    ..Default::default()
                });
                pass.set_pipeline(&blit.pipeline);
                for (&(_, [x0, y0], [w, h]), b) in o.tiles.iter().zip(&binds) {
                    pass.set_scissor_rect(x0, y0, w, h);
                    pass.set_bind_group(0, b, &[]);
                    pass.draw(0..3, 0..1);
                }
            }
            gpu.queue.submit([enc.finish()]);
            gpu.queue.present(frame);
        }
        self.conn.flush()?;
        Ok(())
    }

    /// Hands every output its projectors' images (premultiplied linear
    /// RGBA, this back end's images in order) and presents them.
    pub fn present(&mut self, gpu: &Gpu, images: &[Vec<[f32; 4]>]) -> Result<()> {
        // Nothing reads the windows' events: drop them so they do not pile up.
        while self.conn.poll_for_event()?.is_some() {}
        let rgb: Vec<Vec<u8>> = images.iter().map(|i| crate::output::rgb8(i)).collect();
        for o in &mut self.outputs {
            let (w, h) = (o.config.width, o.config.height);
            let mut bytes = vec![0u8; (w * h * 4) as usize];
            for px in bytes.chunks_exact_mut(4) {
                px[3] = 255;
            }
            for &(i, [x0, y0], [tw, th]) in &o.tiles {
                let src = &rgb[i];
                for y in 0..th {
                    for x in 0..tw {
                        let s = ((y * tw + x) * 3) as usize;
                        let d = (((y0 + y) * w + x0 + x) * 4) as usize;
                        let (r, g, b) = (src[s], src[s + 1], src[s + 2]);
                        let px = if o.bgra {
                            [b, g, r, 255]
                        } else {
                            [r, g, b, 255]
                        };
                        bytes[d..d + 4].copy_from_slice(&px);
                    }
                }
            }
            let frame = acquire(gpu, o)?;
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &frame.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                &bytes,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * w),
                    rows_per_image: Some(h),
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
            gpu.queue.present(frame);
        }
        self.conn.flush()?;
        Ok(())
    }
}

/// The next image of an output's surface, reconfiguring it once where the
/// window changed under it.
fn acquire(gpu: &Gpu, o: &OutputWindow) -> Result<wgpu::SurfaceTexture> {
    for _ in 0..2 {
        match o.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => return Ok(t),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Timeout => {
                gpu.validated("reconfiguring a window's surface", || {
                    o.surface.configure(&gpu.device, &o.config)
                })?;
            }
            other => bail!("output '{}': the window's surface is {other:?}", o.label),
        }
    }
    bail!(
        "output '{}': the window's surface gave no image to present",
        o.label
    )
}

/// [x, y] and [width, height] of the RandR output (monitor) `name`.
fn named_output(conn: &XCBConnection, root: u32, name: &str) -> Result<([i32; 2], [u32; 2])> {
    let monitors = conn.randr_get_monitors(root, true)?.reply()?.monitors;
    let mut names = Vec::new();
    for m in &monitors {
        let n = String::from_utf8_lossy(&conn.get_atom_name(m.name)?.reply()?.name).into_owned();
        if n == name {
            return Ok(([m.x as i32, m.y as i32], [m.width as u32, m.height as u32]));
        }
        names.push(n);
    }
    bail!("no output '{name}' (its outputs: {})", names.join(", "))
}

/// A wgpu surface on window `id`, configured for byte copies of 8-bit
/// colour at the window's size in `mode`.
fn surface(
    gpu: &Gpu,
    conn: &XCBConnection,
    screen: usize,
    id: u32,
    size: [u32; 2],
    mode: PresentMode,
) -> Result<(wgpu::Surface<'static>, wgpu::SurfaceConfiguration, bool)> {
    use raw_window_handle::{XcbDisplayHandle, XcbWindowHandle};
    let target = wgpu::SurfaceTargetUnsafe::RawHandle {
        raw_display_handle: Some(
            XcbDisplayHandle::new(NonNull::new(conn.get_raw_xcb_connection()), screen as i32)
                .into(),
        ),
        raw_window_handle: XcbWindowHandle::new(NonZeroU32::new(id).context("window id 0")?).into(),
    };
    // SAFETY: the connection and the window outlive the surface: both
    // belong to the Presenter, which drops its surfaces first.
    let surface = unsafe { gpu.instance.create_surface_unsafe(target) }
        .context("cannot make a GPU surface on the window")?;
    let caps = surface.get_capabilities(&gpu.adapter);
    if caps.formats.is_empty() {
        bail!("the GPU '{}' cannot present to this window", gpu.info.name);
    }
    use wgpu::TextureFormat as F;
    let format = [
        F::Bgra8Unorm,
        F::Rgba8Unorm,
        F::Bgra8UnormSrgb,
        F::Rgba8UnormSrgb,
    ]
    .into_iter()
    .find(|f| caps.formats.contains(f))
    .with_context(|| format!("no 8-bit colour format among {:?}", caps.formats))?;
    if !caps.usages.contains(wgpu::TextureUsages::COPY_DST) {
        bail!(
            "the window's surface takes no copies (usages {:?})",
            caps.usages
        );
    }
    let present_mode = match mode {
        PresentMode::Fifo => wgpu::PresentMode::Fifo,
        PresentMode::Immediate => wgpu::PresentMode::Immediate,
        PresentMode::Mailbox => wgpu::PresentMode::Mailbox,
    };
    if !caps.present_modes.contains(&present_mode) {
        bail!(
            "present mode {mode:?} is not offered (the surface has {:?})",
            caps.present_modes
        );
    }
    let usage =
        wgpu::TextureUsages::COPY_DST | (caps.usages & wgpu::TextureUsages::RENDER_ATTACHMENT);
    let config = wgpu::SurfaceConfiguration {
        usage,
        format,
        color_space: wgpu::SurfaceColorSpace::Auto,
        width: size[0],
        height: size[1],
        present_mode,
        desired_maximum_frame_latency: 2,
        alpha_mode: wgpu::CompositeAlphaMode::Auto,
        view_formats: vec![],
    };
    gpu.validated("configuring a window's surface", || {
        surface.configure(&gpu.device, &config)
    })?;
    Ok((
        surface,
        config,
        matches!(format, F::Bgra8Unorm | F::Bgra8UnormSrgb),
    ))
}

/// The pipeline that draws projectors' images from the ray caster's image
/// buffer into a window (`shaders/present.wgsl`), for one surface format.
struct Blit {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// Per tile of the output: its [`TileUniform`].
    tiles: Vec<wgpu::Buffer>,
    thresholds: wgpu::Buffer,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TileUniform {
    offset: u32,
    width: u32,
    x0: u32,
    y0: u32,
}

/// The shader, validated without a GPU by a test.
const BLIT: &str = include_str!("../../shaders/present.wgsl");

impl Blit {
    fn new(gpu: &Gpu, format: wgpu::TextureFormat, tiles: usize) -> Result<Self> {
        use wgpu::util::DeviceExt;
        let dev = &gpu.device;
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("present"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform),
                entry(1, wgpu::BufferBindingType::Storage { read_only: true }),
                entry(2, wgpu::BufferBindingType::Uniform),
            ],
        });
        let module = gpu.validated("shaders/present.wgsl", || {
            dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("present.wgsl"),
                source: wgpu::ShaderSource::Wgsl(BLIT.into()),
            })
        })?;
        let pl = dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("present"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = gpu.validated("the present pipeline", || {
            dev.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("present"),
                layout: Some(&pl),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
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
        let t = crate::output::srgb_thresholds();
        let thresholds = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sRGB thresholds"),
            contents: bytemuck::cast_slice(&t),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let tiles = (0..tiles)
            .map(|_| {
                dev.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("present tile"),
                    size: std::mem::size_of::<TileUniform>() as u64,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect();
        Ok(Blit {
            pipeline,
            layout,
            tiles,
            thresholds,
        })
    }
}

impl Blit {
    /// The bind group of one tile over the image buffer.
    fn bind(&self, gpu: &Gpu, tile: &wgpu::Buffer, image: &wgpu::Buffer) -> wgpu::BindGroup {
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("present tile"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: tile.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: image.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: self.thresholds.as_entire_binding(),
                },
            ],
        })
    }
}

#[cfg(test)]
mod tests {
    /// The present shader parses and validates with naga, without a GPU.
    #[test]
    fn the_shader_validates() {
        let m = wgpu::naga::front::wgsl::parse_str(super::BLIT).unwrap();
        wgpu::naga::valid::Validator::new(
            wgpu::naga::valid::ValidationFlags::all(),
            wgpu::naga::valid::Capabilities::all(),
        )
        .validate(&m)
        .unwrap();
    }
}
