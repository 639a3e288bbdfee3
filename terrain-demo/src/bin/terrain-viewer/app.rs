//! The viewer's event loop (winit's `ApplicationHandler`): the window and its events, turned
//! into [`InputEvent`]s and handled with the scripted ones; each frame applies the commands,
//! moves the camera, draws, and updates the on-screen timings and the title.

use crate::fly_camera::FlyCamera;
use crate::gpu::{FrameTimes, Gpu, GpuOptions};
use crate::input::{Button, Command, InputEvent, InputState, Key};
use crate::input_script::InputScript;
use crate::modes::{DetailMode, LodMode};
use crate::picking::{cursor_ray, hit_terrain};
use crate::terrain::{StampKind, Terrain};
use anyhow::{Context, Result};
use glam::{UVec2, Vec2, Vec3};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_core::bilinear;
use terrain_gpu::{GpuStamp, StampOp};
use terrain_physics::{CollisionMirror, DeformationBound, ReadbackScheduler, SchedulerConfig};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::ActiveEventLoop;
use winit::keyboard::PhysicalKey;
use winit::window::{Window, WindowId};

/// Seconds per frame of scripted runs (`--frames`): the same flight whatever the frame rate.
const SCRIPTED_DT: f32 = 1.0 / 30.0;
/// The longest step of an interactive frame (a stall does not throw the camera far).
const MAX_DT: f32 = 0.1;
/// How often the on-screen text and the title change.
const TEXT_EVERY: Duration = Duration::from_millis(250);
/// Frames left out of the run's mean timings (pipelines and caches warming up).
const WARMUP_FRAMES: u32 = 3;

/// What the command line asks of the app.
#[derive(Debug)]
pub struct Settings {
    pub resolution: UVec2,
    pub frames: Option<u32>,
    pub screenshot: Option<PathBuf>,
    pub script: Option<InputScript>,
    pub gpu: GpuOptions,
}

/// Sums of the frames' timings, for a mean.
#[derive(Debug, Default, Clone, Copy)]
struct Sums {
    frames: u32,
    frame_ms: f64,
    lod_ms: f64,
    render_ms: f64,
    present_ms: f64,
}

impl Sums {
    fn add(&mut self, frame_ms: f64, t: &FrameTimes) {
        self.frames += 1;
        self.frame_ms += frame_ms;
        self.lod_ms += t.lod_ms;
        self.render_ms += t.render_ms;
        self.present_ms += t.present_ms;
    }

    fn mean(&self, v: f64) -> f64 {
        v / f64::from(self.frames.max(1))
    }
}

/// The viewer.
pub struct App {
    settings: Settings,
    /// The CPU's copy of the map (picking, the camera's ground): never stamped, it follows the
    /// GPU map through `scheduler`'s readbacks into `mirror`.
    terrain: Terrain,
    mirror: CollisionMirror,
    scheduler: ReadbackScheduler,
    camera: FlyCamera,
    input: InputState,
    commands: Vec<Command>,
    window: Option<Arc<Window>>,
    gpu: Option<Gpu>,
    lod: LodMode,
    detail: DetailMode,
    /// Frames drawn.
    frame: u32,
    last_frame_at: Option<Instant>,
    /// Timings since the text last changed, and over the whole run after the warm-up.
    interval: Sums,
    run: Sums,
    text_at: Instant,
    /// The last stamp's milliseconds (GPU stamp, GPU normals), and what it was.
    last_stamp: Option<(StampKind, f64, f64)>,
    wireframe_warned: bool,
    /// Set when the app stops on an error.
    pub error: Option<anyhow::Error>,
}

impl App {
    /// A viewer of `terrain`, the camera over its first third looking along it.
    pub fn new(settings: Settings, terrain: Terrain) -> Result<Self> {
        let extent = terrain.map.extent_m();
        let start = Vec2::new(extent.x * 0.3, extent.y * 0.5);
        let ground = bilinear(&terrain.map, start)?;
        let mirror = CollisionMirror::from_map(&terrain.map)?;
        let config = SchedulerConfig {
            max_in_flight: crate::gpu::READBACK_RING,
            ..SchedulerConfig::default()
        };
        let scheduler = ReadbackScheduler::for_mirror(&mirror, config)?;
        Ok(Self {
            mirror,
            scheduler,
            settings,
            camera: FlyCamera::new(Vec3::new(start.x, ground + 7.0, start.y), 0.3, -0.3),
            terrain,
            input: InputState::default(),
            commands: Vec::new(),
            window: None,
            gpu: None,
            lod: LodMode::Clipmap,
            detail: DetailMode::None,
            frame: 0,
            last_frame_at: None,
            interval: Sums::default(),
            run: Sums::default(),
            text_at: Instant::now(),
            last_stamp: None,
            wireframe_warned: false,
            error: None,
        })
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: anyhow::Error) {
        self.error.get_or_insert(e);
        event_loop.exit();
    }

    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let size = self.settings.resolution;
        let attributes = Window::default_attributes()
            .with_title("terrain viewer")
            .with_inner_size(PhysicalSize::new(size.x, size.y));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .context("cannot open the viewer's window")?,
        );
        let gpu = Gpu::new(
            event_loop,
            window.clone(),
            &self.terrain.map,
            &self.terrain.footprint,
            self.settings.gpu,
        )?;
        println!(
            "viewer: {} x {} map on {}; {}",
            self.terrain.map.size().x,
            self.terrain.map.size().y,
            gpu.adapter(),
            if gpu.has_wireframe() {
                "wireframe available (F)"
            } else {
                "wireframe unavailable (the adapter lacks POLYGON_MODE_LINE)"
            }
        );
        window.request_redraw();
        self.window = Some(window);
        self.gpu = Some(gpu);
        Ok(())
    }

    /// One input event, from the window or the script.
    fn input(&mut self, event: InputEvent) {
        self.input.handle(event, &mut self.commands);
    }

    fn run_command(&mut self, command: Command, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(gpu) = self.gpu.as_mut() else {
            return Ok(());
        };
        match command {
            Command::Stamp { button, cursor } => {
                let kind = match button {
                    Button::Left => StampKind::Crater,
                    Button::Right => StampKind::Footprint,
                };
                let camera = self.camera.camera();
                let hit = cursor_ray(&camera, cursor, gpu.size())
                    .and_then(|dir| hit_terrain(&self.terrain.map, camera.position, dir));
                let Some(hit) = hit else {
                    println!("viewer: no terrain under the cursor");
                    return Ok(());
                };
                let at = Vec2::new(hit.x, hit.z);
                let placement = Terrain::placement(kind, at, self.camera.yaw)?;
                let op = StampOp {
                    stamp: GpuStamp::Gaussian(&self.terrain.crater),
                    placement,
                    blend: terrain_core::Blend::Add,
                };
                let (stamp_ms, normals_ms, dirty) = gpu.stamp(&op, kind == StampKind::Footprint)?;
                // The CPU's map learns the new heights through the readback only.
                let bound =
                    DeformationBound::additive(placement.intensity, self.terrain.map.encoding())?;
                for rect in dirty {
                    self.scheduler
                        .note_deformation(rect, bound, Instant::now())?;
                }
                self.last_stamp = Some((kind, stamp_ms, normals_ms));
                println!(
                    "viewer: {} at ({:.1}, {:.1}) m: stamp {stamp_ms:.2} ms, normals {normals_ms:.2} ms",
                    kind.name(),
                    at.x,
                    at.y
                );
            }
            Command::ToggleWireframe => {
                if gpu.has_wireframe() {
                    let on = !gpu.wireframe();
                    gpu.set_wireframe(on)?;
                    println!("viewer: wireframe {}", if on { "on" } else { "off" });
                } else if !self.wireframe_warned {
                    self.wireframe_warned = true;
                    println!("viewer: wireframe unavailable: the adapter lacks POLYGON_MODE_LINE");
                }
            }
            Command::CycleLod => {
                self.lod = self.lod.next();
                println!("viewer: LOD mode {}", self.lod.name());
            }
            Command::CycleDetail => {
                self.detail = self.detail.next();
                println!("viewer: detail mode {}", self.detail.name());
            }
            Command::Levels(delta) => {
                let levels = gpu.levels().saturating_add_signed(delta);
                gpu.set_levels(levels)?;
                println!("viewer: {} clipmap levels", gpu.levels());
            }
            Command::Quit => event_loop.exit(),
        }
        self.text_at = Instant::now() - TEXT_EVERY;
        Ok(())
    }

    fn frame(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(size) = self.gpu.as_ref().map(Gpu::size) else {
            return Ok(());
        };
        let now = Instant::now();
        let frame_ms = self.last_frame_at.map(|t| (now - t).as_secs_f64() * 1e3);
        self.last_frame_at = Some(now);
        let dt = match (self.settings.frames, frame_ms) {
            (Some(_), _) => SCRIPTED_DT,
            (None, Some(ms)) => (ms as f32 / 1e3).min(MAX_DT),
            (None, None) => 0.0,
        };

        if let Some(script) = &self.settings.script {
            for event in script.events(self.frame, size, self.input.cursor()) {
                self.input.handle(event, &mut self.commands);
            }
        }
        for command in std::mem::take(&mut self.commands) {
            self.run_command(command, event_loop)?;
        }
        if let Some(gpu) = self.gpu.as_mut() {
            let report = gpu.read_back(&mut self.scheduler, &self.mirror, now)?;
            for rect in &report.applied_rects {
                self.mirror.copy_into(*rect, &mut self.terrain.map)?;
            }
        }
        self.camera.look(self.input.take_look());
        self.camera.scroll(self.input.take_scroll());
        let map = &self.terrain.map;
        self.camera
            .step(dt, self.input.motion(), |p| bilinear(map, p).unwrap_or(0.0));

        if self.text_at.elapsed() >= TEXT_EVERY {
            self.update_text();
        }
        let Some(gpu) = self.gpu.as_mut() else {
            return Ok(());
        };
        let times = gpu.render(&self.camera.camera())?;
        if let (Some(times), Some(ms)) = (times, frame_ms) {
            self.interval.add(ms, &times);
            if self.frame >= WARMUP_FRAMES {
                self.run.add(ms, &times);
            }
        }
        self.frame += 1;

        if self.settings.frames.is_some_and(|n| self.frame >= n) {
            self.finish(event_loop)?;
        } else if let Some(window) = &self.window {
            window.request_redraw();
        }
        Ok(())
    }

    /// The on-screen lines and the title, from the timings since the last update.
    fn update_text(&mut self) {
        let Some(gpu) = self.gpu.as_mut() else {
            return;
        };
        let s = self.interval;
        let frame_ms = s.mean(s.frame_ms);
        let fps = if frame_ms > 0.0 { 1e3 / frame_ms } else { 0.0 };
        let stamp = match self.last_stamp {
            Some((kind, stamp, normals)) => {
                format!("{} {stamp:.1} normals {normals:.1} ms", kind.name())
            }
            None => "click: crater  right: footprint".into(),
        };
        let wireframe = match (gpu.has_wireframe(), gpu.wireframe()) {
            (false, _) => "n/a",
            (true, true) => "on",
            (true, false) => "off",
        };
        let lines = vec![
            format!("{frame_ms:5.1} ms {fps:5.1} fps"),
            format!(
                "render {:.1} lod {:.1} present {:.1} ms",
                s.mean(s.render_ms),
                s.mean(s.lod_ms),
                s.mean(s.present_ms)
            ),
            stamp,
            format!(
                "LOD {} {} lv  detail {}",
                self.lod.name(),
                gpu.levels(),
                self.detail.name()
            ),
            format!("wireframe {wireframe}  speed {:.1} m/s", self.camera.speed),
        ];
        gpu.set_text(lines);
        if let Some(window) = &self.window {
            window.set_title(&format!(
                "terrain viewer - {fps:.0} fps - {}",
                gpu.adapter()
            ));
        }
        self.interval = Sums::default();
        self.text_at = Instant::now();
    }

    /// The end of a `--frames` run: the screenshot, the mean timings, and exit.
    fn finish(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(gpu) = self.gpu.as_ref() else {
            return Ok(());
        };
        let s = self.run;
        let size = gpu.size();
        if s.frames == 0 {
            // Every frame was warm-up: no mean to give.
            println!(
                "viewer: {} frames at {}x{} on {}: all warm-up ({WARMUP_FRAMES}), none timed",
                self.frame,
                size.x,
                size.y,
                gpu.adapter()
            );
        } else {
            println!(
                "viewer: {} frames at {}x{} on {}: mean frame {:.1} ms ({:.1} fps), render {:.1} ms, \
             lod {:.2} ms, present {:.1} ms (over {} frames after {WARMUP_FRAMES} warm-up)",
                self.frame,
                size.x,
                size.y,
                gpu.adapter(),
                s.mean(s.frame_ms),
                1e3 / s.mean(s.frame_ms).max(1e-9),
                s.mean(s.render_ms),
                s.mean(s.lod_ms),
                s.mean(s.present_ms),
                s.frames
            );
        }
        if let Some(path) = &self.settings.screenshot {
            let image = gpu.read_frame()?;
            terrain_core::io::write_png_rgba8(path, &image)
                .with_context(|| format!("cannot write the screenshot {}", path.display()))?;
            println!("viewer: wrote {}", path.display());
        }
        event_loop.exit();
        Ok(())
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_none()
            && let Err(e) = self.start(event_loop)
        {
            self.fail(event_loop, e);
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(gpu) = self.gpu.as_mut() {
                    gpu.resize(UVec2::new(size.width, size.height));
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key
                    && let Some(key) = Key::from_code(code)
                {
                    self.input(InputEvent::Key {
                        key,
                        pressed: event.state == ElementState::Pressed,
                    });
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.input(InputEvent::Cursor(Vec2::new(
                    position.x as f32,
                    position.y as f32,
                )));
            }
            WindowEvent::MouseInput { state, button, .. } => {
                let button = match button {
                    MouseButton::Left => Button::Left,
                    MouseButton::Right => Button::Right,
                    _ => return,
                };
                self.input(InputEvent::Button {
                    button,
                    pressed: state == ElementState::Pressed,
                });
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                self.input(InputEvent::Scroll(steps));
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.frame(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            _ => {}
        }
    }
}
