//! The viewer's GPU side: the device on an adapter that can present to the window, the
//! terrain on the GPU (terrain-gpu's `DeformableMap`: heights, derivative normals, the
//! passes), and each frame drawn by terrain-gpu's caller's-pass renderers (`SkyPass`,
//! `ClipmapRenderer`) into the viewer's own colour and depth textures, the overlay on top,
//! then copied to the window.
//! The colour texture is also what `--screenshot` reads back.

use crate::overlay::Overlay;
use crate::present::Present;
use anyhow::{Context, Result, anyhow, bail};
use glam::{UVec2, Vec2};
use std::sync::{Arc, Mutex};
use std::time::Instant;
use terrain_core::DirtyRect;
use terrain_core::{CoarseMap, Grid, TextureStamp};
use terrain_gpu::{
    Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, DeformableMap, DepthConvention,
    GpuRegionSource, GpuTextureStamp, GpuTimer, MapUse, RegionReadback, SkyColors, SkyPass,
    StampOp, TargetFormat, TerrainStyle,
};
use terrain_lod::{ClipmapLayout, Frustum};
use terrain_physics::{CollisionMirror, ReadbackScheduler, UpdateReport};
use winit::event_loop::ActiveEventLoop;
use winit::window::Window;

/// Staging buffers of the map's readback ring (the scheduler's `max_in_flight`).
pub const READBACK_RING: usize = 16;

/// Clipmap vertices per level side (as the capture demo).
pub const CLIPMAP_N: u32 = 255;
/// The colour format of the viewer's frame: sRGB, so the renderers' linear output is encoded
/// once, and the bytes read back for a screenshot are those displayed.
const FRAME_COLOR: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const FRAME_DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// How the viewer asks for its device and surface.
#[derive(Debug, Clone, Copy)]
pub struct GpuOptions {
    /// Wait for the display's refresh (`Fifo`) or not (`AutoNoVsync`).
    pub vsync: bool,
    /// Clipmap levels at start.
    pub levels: u32,
}

/// Milliseconds of one drawn frame's steps.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameTimes {
    /// Clipmap placement and culling (CPU).
    pub lod_ms: f64,
    /// Sky, terrain and overlay into the frame texture: submit until done.
    pub render_ms: f64,
    /// Acquiring the window's texture, the copy, and presenting.
    pub present_ms: f64,
}

/// The viewer's colour and depth textures of the window's size.
#[derive(Debug)]
struct FrameTextures {
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
}

impl FrameTextures {
    fn new(device: &wgpu::Device, size: UVec2) -> Self {
        let texture = |label, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size.x,
                    height: size.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = texture(
            "viewer frame",
            FRAME_COLOR,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = texture(
            "viewer depth",
            FRAME_DEPTH,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        Self {
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
        }
    }
}

/// Everything the viewer keeps on the GPU.
pub struct Gpu {
    // The surface borrows the window through its Arc; the instance outlives both.
    surface: wgpu::Surface<'static>,
    _instance: wgpu::Instance,
    config: wgpu::SurfaceConfiguration,
    surface_view_format: wgpu::TextureFormat,
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: String,
    errors: Arc<Mutex<Vec<String>>>,
    frame: FrameTextures,
    present: Present,
    overlay: Overlay,
    /// The map, its normals and the passes that deform it.
    ground: DeformableMap,
    footprint: GpuTextureStamp,
    sky: SkyPass,
    renderer: ClipmapRenderer,
    layout: ClipmapLayout,
    style: TerrainStyle,
    height_range: (f32, f32),
    timer: GpuTimer,
    /// The ring the CPU's copy of the map is read back through (never waiting).
    readback: RegionReadback,
}

impl Gpu {
    /// Makes the device on an adapter that can present to `window` (Vulkan, else GL; or what
    /// `WGPU_BACKEND` names), uploads `map` and builds every pass.
    pub fn new(
        event_loop: &ActiveEventLoop,
        window: Arc<Window>,
        map: &CoarseMap,
        footprint: &TextureStamp,
        options: GpuOptions,
    ) -> Result<Self> {
        let tries = match wgpu::Backends::from_env() {
            Some(forced) => vec![forced],
            None => vec![wgpu::Backends::VULKAN, wgpu::Backends::GL],
        };
        let mut reasons = Vec::new();
        for backends in tries {
            let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
                backends,
                flags: wgpu::InstanceFlags::from_build_config().with_env(),
                ..wgpu::InstanceDescriptor::new_with_display_handle(Box::new(
                    event_loop.owned_display_handle(),
                ))
            });
            let surface = match instance.create_surface(window.clone()) {
                Ok(s) => s,
                Err(e) => {
                    reasons.push(format!("{backends:?}: no surface ({e})"));
                    continue;
                }
            };
            let adapter =
                pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    force_fallback_adapter: false,
                    compatible_surface: Some(&surface),
                    ..Default::default()
                }));
            match adapter {
                Ok(adapter) => {
                    return Self::on_adapter(
                        instance, surface, adapter, &window, map, footprint, options,
                    );
                }
                Err(e) => reasons.push(format!("{backends:?}: {e}")),
            }
        }
        bail!(
            "no GPU adapter can present to the window ({})",
            reasons.join("; ")
        )
    }

    fn on_adapter(
        instance: wgpu::Instance,
        surface: wgpu::Surface<'static>,
        adapter: wgpu::Adapter,
        window: &Window,
        map: &CoarseMap,
        footprint: &TextureStamp,
        options: GpuOptions,
    ) -> Result<Self> {
        let info = adapter.get_info();
        let adapter_name = format!("{} ({})", info.name, info.backend.to_str());
        terrain_gpu::check_limits(&adapter.limits(), map.size(), MapUse::Coarse)
            .with_context(|| format!("{adapter_name} cannot hold a {} map", map.size()))?;
        let wanted = terrain_gpu::OPTIONAL_FEATURES | wgpu::Features::POLYGON_MODE_LINE;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("viewer device"),
            required_features: adapter.features() & wanted,
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .with_context(|| format!("no device on {adapter_name}"))?;
        // Errors of recorded work surface at submit: collect them and stop with them after the
        // frame, instead of wgpu's default panic.
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut list) = sink.lock()
                && list.len() < 16
            {
                list.push(e.to_string());
            }
        }));

        let caps = surface.get_capabilities(&adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| {
                matches!(
                    f,
                    wgpu::TextureFormat::Bgra8UnormSrgb | wgpu::TextureFormat::Rgba8UnormSrgb
                )
            })
            .or_else(|| caps.formats.iter().copied().find(|f| f.is_srgb()))
            .or_else(|| caps.formats.first().copied())
            .context("the window's surface offers no format")?;
        // A non-sRGB surface is drawn through an sRGB view, so its bytes are the frame's.
        let surface_view_format = format.add_srgb_suffix();
        let present_mode = if options.vsync {
            wgpu::PresentMode::AutoVsync
        } else {
            wgpu::PresentMode::AutoNoVsync
        };
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode,
            desired_maximum_frame_latency: 2,
            alpha_mode: wgpu::CompositeAlphaMode::Auto,
            view_formats: if surface_view_format == format {
                vec![]
            } else {
                vec![surface_view_format]
            },
        };
        surface.configure(&device, &config);

        let target = TargetFormat {
            color: FRAME_COLOR,
            depth: FRAME_DEPTH,
            sample_count: 1,
            depth_convention: DepthConvention::Forward,
        };
        let ground = DeformableMap::new(&device, &queue, map)?;
        let layout = ClipmapLayout::new(CLIPMAP_N, options.levels)?;
        let (lo, hi) = map.encoding().range::<u16>();
        let frame = FrameTextures::new(&device, UVec2::new(config.width, config.height));
        let mut present = Present::new(&device, surface_view_format)?;
        present.set_source(&device, &frame.color_view);
        let gpu = Self {
            overlay: Overlay::new(&device, FRAME_COLOR)?,
            footprint: GpuTextureStamp::new(&device, footprint)?,
            sky: SkyPass::new(&device, &target)?,
            renderer: ClipmapRenderer::new(&device, &target, &layout)?,
            timer: GpuTimer::new(&device, &queue),
            readback: RegionReadback::new(&device, READBACK_RING)?,
            layout,
            ground,
            style: TerrainStyle {
                ramp: (lo, hi),
                fog_density: 0.008,
                ..TerrainStyle::default()
            },
            height_range: (lo, hi),
            frame,
            present,
            surface,
            _instance: instance,
            config,
            surface_view_format,
            device,
            queue,
            adapter: adapter_name,
            errors,
        };
        gpu.check()?;
        Ok(gpu)
    }

    /// The adapter's name and backend.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// The frame's size in pixels.
    pub fn size(&self) -> Vec2 {
        Vec2::new(self.config.width as f32, self.config.height as f32)
    }

    /// Fails with the errors wgpu reported since the last call.
    pub fn check(&self) -> Result<()> {
        let errors: Vec<String> = match self.errors.lock() {
            Ok(mut list) => list.drain(..).collect(),
            Err(poisoned) => poisoned.into_inner().drain(..).collect(),
        };
        if errors.is_empty() {
            Ok(())
        } else {
            Err(anyhow!("the GPU reported: {}", errors.join("; ")))
        }
    }

    /// Follows the window to `size` pixels (nothing for an empty window).
    pub fn resize(&mut self, size: UVec2) {
        if size.x == 0 || size.y == 0 || (size.x, size.y) == (self.config.width, self.config.height)
        {
            return;
        }
        self.config.width = size.x;
        self.config.height = size.y;
        self.surface.configure(&self.device, &self.config);
        self.frame = FrameTextures::new(&self.device, size);
        self.present
            .set_source(&self.device, &self.frame.color_view);
    }

    /// Whether the clipmap can be drawn as wireframe (the device has `POLYGON_MODE_LINE`).
    pub fn has_wireframe(&self) -> bool {
        self.renderer.has_wireframe()
    }

    /// Turns wireframe on or off (refused without [`Gpu::has_wireframe`]).
    pub fn set_wireframe(&mut self, on: bool) -> Result<()> {
        Ok(self.renderer.set_wireframe(on)?)
    }

    /// Whether wireframe is on.
    pub fn wireframe(&self) -> bool {
        self.renderer.wireframe()
    }

    /// Shows `lines` on screen from the next frame (uploaded only when they changed).
    pub fn set_text(&mut self, lines: Vec<String>) {
        self.overlay.set_text(&self.queue, lines);
    }

    /// Clipmap levels drawn.
    pub fn levels(&self) -> u32 {
        self.layout.levels()
    }

    /// Rebuilds the clipmap renderer with `levels` levels (2 to terrain-lod's maximum),
    /// keeping wireframe as it was.
    pub fn set_levels(&mut self, levels: u32) -> Result<()> {
        let levels = levels.clamp(2, terrain_lod::clipmap::MAX_LEVELS);
        if levels == self.layout.levels() {
            return Ok(());
        }
        let layout = ClipmapLayout::new(CLIPMAP_N, levels)?;
        let target = *self.renderer.target();
        let wireframe = self.renderer.wireframe();
        self.renderer = ClipmapRenderer::new(&self.device, &target, &layout)?;
        self.renderer.set_wireframe(wireframe)?;
        self.layout = layout;
        Ok(())
    }

    /// Applies a stamp to the GPU map (the footprint texture when `footprint`, else `op`'s
    /// own stamp) and regenerates the normals of the texels it changed; returns the
    /// milliseconds of each (submit until done) and the rects it changed.
    pub fn stamp(
        &mut self,
        op: &StampOp<'_>,
        footprint: bool,
    ) -> Result<(f64, f64, Vec<DirtyRect>)> {
        let (device, queue) = (&self.device, &self.queue);
        let op = if footprint {
            StampOp {
                stamp: terrain_gpu::GpuStamp::Texture(&self.footprint),
                ..*op
            }
        } else {
            *op
        };
        let mut dirty = Vec::new();
        let stamp = self.timer.time(device, queue, |encoder| {
            dirty = self.ground.encode_stamp(device, queue, encoder, &op)?;
            Ok(())
        })?;
        let normals = self.timer.time(device, queue, |encoder| {
            self.ground.encode_normals(device, queue, encoder, &dirty)
        })?;
        self.ground.recall();
        self.check()?;
        Ok((stamp.ms, normals.ms, dirty))
    }

    /// Reads the GPU map's deformed regions back for `scheduler` into `mirror` (never waits):
    /// the CPU's copy of the map follows the GPU through this only.
    pub fn read_back(
        &mut self,
        scheduler: &mut ReadbackScheduler,
        mirror: &CollisionMirror,
        now: Instant,
    ) -> Result<UpdateReport> {
        let mut source = GpuRegionSource::new(
            &self.device,
            &self.queue,
            self.ground.heights(),
            &mut self.readback,
        );
        // A busy ring keeps the rects dirty (`RegionSource::is_busy`).
        Ok(scheduler.update(now, &mut source, mirror)?)
    }

    /// Draws the frame seen by `camera` and presents it; `None` when the window has no
    /// texture to show it in this time (minimised, or reconfigured: the next frame draws).
    pub fn render(&mut self, camera: &Camera) -> Result<Option<FrameTimes>> {
        let (device, queue) = (&self.device, &self.queue);
        let size = UVec2::new(self.config.width, self.config.height);
        let aspect = size.x as f32 / size.y as f32;
        let t = Instant::now();
        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        let placement = self.layout.place(
            Vec2::new(camera.position.x, camera.position.z),
            self.ground.heights().texel_size(),
            self.height_range,
            Some(&frustum),
        )?;
        let lod_ms = t.elapsed().as_secs_f64() * 1e3;
        let view = ClipmapView {
            surface: ClipmapSurface::Coarse {
                map: self.ground.heights(),
                normals: self.ground.normals(),
            },
            frame: &placement,
            camera,
            style: &self.style,
            target_size: size,
        };
        self.overlay.prepare(queue, size.as_vec2());
        let render = self.timer.time(device, queue, |encoder| {
            self.sky.prepare(
                queue,
                camera.view_proj_relative(aspect),
                &SkyColors::default(),
            )?;
            self.renderer.prepare(device, queue, &view)?;
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("viewer terrain"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &self.frame.color_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &self.frame.depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Discard,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                self.sky.draw(&mut pass);
                self.renderer.draw(&mut pass);
            }
            // The text over the terrain: a pass of its own, without depth.
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("viewer overlay"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.frame.color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.overlay.draw(&mut pass);
            Ok(())
        })?;
        self.check()?;

        let t = Instant::now();
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(None);
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.device, &self.config);
                return Ok(None);
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                self.check()?;
                bail!("the window's surface texture could not be acquired");
            }
        };
        let target = texture.texture.create_view(&wgpu::TextureViewDescriptor {
            format: Some(self.surface_view_format),
            ..Default::default()
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.present.encode(&mut encoder, &target);
        self.queue.submit([encoder.finish()]);
        self.queue.present(texture);
        self.check()?;
        Ok(Some(FrameTimes {
            lod_ms,
            render_ms: render.ms,
            present_ms: t.elapsed().as_secs_f64() * 1e3,
        }))
    }

    /// The last frame drawn, as RGBA8 rows from the top (the bytes the window shows).
    pub fn read_frame(&self) -> Result<Grid<[u8; 4]>> {
        let image = terrain_gpu::read_texture_rgba8(&self.device, &self.queue, &self.frame.color)?;
        self.check()?;
        Ok(image)
    }
}
