//! The windowed viewer: a winit window whose frames go through the same
//! [`Renderer`] as the headless renders (selection, expansion or mesh shaders, draw), blitted
//! into the swapchain ([`Renderer::render_to_swapchain`]).
//!
//! Keys: right mouse button held (or Tab to toggle) captures the cursor for mouse look; W/A/S/D
//! fly, E or Space up, Q or Ctrl down, Shift 5× faster; +/− or the mouse wheel scale τ; 1–5
//! pick the mode (shaded, cluster, group, level, error); R resets the camera; P writes a
//! screenshot; Esc quits. Stats (clusters, triangles, GPU ms per pass, frame rate) go to the
//! window title four times a second.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context as _, Result};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{DeviceEvent, DeviceId, ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::raw_window_handle::HasDisplayHandle as _;
use winit::window::{CursorGrabMode, Window, WindowId};

use crate::camera::Camera;
use crate::fly::{FlyCamera, Movement};
use crate::gpu_types::{FLAG_FRUSTUM_CULL, MODE_CLUSTER, MODE_ERROR, MODE_GROUP, MODE_LEVEL, MODE_SHADED};
use crate::image::write_png;
use crate::scene::SceneData;
use crate::vk::{
    ContextOptions, Device, DeviceInfo, Frame, MessageCounts, Renderer, RendererOptions, Surface, Swapchain,
};

/// τ range the keys and the wheel keep to, pixels.
const TAU_RANGE: (f32, f32) = (1.0 / 64.0, 1024.0);
/// τ factor of one +/− press or wheel notch.
const TAU_STEP: f32 = 1.25;
/// How often the title's stats are refreshed.
const TITLE_INTERVAL: Duration = Duration::from_millis(250);

/// What the viewer starts with.
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// Shown in the title.
    pub label: String,
    /// Initial window size, pixels.
    pub size: (u32, u32),
    /// Initial τ, pixels.
    pub tau: f32,
    /// Initial `MODE_*`.
    pub mode: u32,
    /// Initial eye (object space), looking at the model's centre; `None`: the headless default.
    pub eye: Option<[f32; 3]>,
    /// Quit after this many presented frames (tests, CI); `None`: run until closed.
    pub frames: Option<u32>,
    /// Where the final frame (and P) writes a screenshot, read back from the presented image.
    pub screenshot: Option<PathBuf>,
    /// Renderer choices (draw path).
    pub renderer: RendererOptions,
    /// Device choices; `display` is filled in from the event loop.
    pub context: ContextOptions,
}

/// What a viewer session did.
#[derive(Debug)]
pub struct ViewerReport {
    /// The device it ran on.
    pub device: DeviceInfo,
    /// The renderer's draw path, in words.
    pub path: &'static str,
    /// Frames presented.
    pub frames: u32,
    /// The last frame's size, counts and GPU times (no pixels).
    pub last: Option<Frame>,
    /// Screenshots written.
    pub screenshots: Vec<PathBuf>,
    /// Validation messages (all zero without validation); complete: every Vulkan object of the
    /// session was destroyed before this report was made.
    pub counts: Arc<MessageCounts>,
}

/// Whether a window system is reachable according to the environment (X11 `DISPLAY` or
/// `WAYLAND_DISPLAY`).
pub fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"].iter().any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// Opens a window and runs the viewer until Esc, the window is closed, or `options.frames`.
pub fn run(scene: &SceneData, cluster_count: u32, options: ViewerOptions) -> Result<ViewerReport> {
    if !display_available() {
        bail!(
            "no display (neither DISPLAY nor WAYLAND_DISPLAY is set): use --headless with --out, --verify or --bench"
        );
    }
    let event_loop = EventLoop::new().context("cannot open the display (use --headless to render without one)")?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let display = event_loop.display_handle().context("display handle")?.as_raw();
    let device = Device::new(&ContextOptions { display: Some(display), ..options.context.clone() })?;
    let counts = device.counts.clone();
    let info = device.info.clone();
    println!("device: {}", info.summary());
    println!("validation: {}", if options.context.validation { "on" } else { "off" });
    let renderer = Renderer::new(&device, scene, options.renderer.clone())?;
    let path = renderer.path_name();
    println!("draw path: {path}");
    let (w, h) = options.size;
    let fly = match options.eye {
        Some(eye) => FlyCamera::looking_at(eye, &scene.bounds),
        None => FlyCamera::framing(&scene.bounds, w, h),
    };
    let mut app = Viewer {
        swapchain: None,
        surface: None,
        window: None,
        renderer,
        device,
        scene_grid: scene.grid,
        cluster_count,
        start: fly,
        fly,
        tau: options.tau.clamp(TAU_RANGE.0, TAU_RANGE.1),
        mode: options.mode,
        keys: HashSet::new(),
        looking: false,
        captured: false,
        swapchain_stale: true,
        screenshot_now: false,
        frames: 0,
        last_frame_time: None,
        title_time: Instant::now(),
        title_frames: 0,
        last: None,
        screenshots: Vec::new(),
        error: None,
        options,
    };
    event_loop.run_app(&mut app).context("window event loop")?;
    let (error, frames, last, screenshots) =
        (app.error.take(), app.frames, app.last.take(), std::mem::take(&mut app.screenshots));
    // The swapchain, surface, window, renderer and device go here, so that the caller's
    // `counts` holds every message of the session.
    drop(app);
    if let Some(e) = error {
        return Err(e);
    }
    Ok(ViewerReport { device: info, path, frames, last, screenshots, counts })
}

/// The viewer's state. Field order is drop order: the swapchain before its surface (which
/// holds the window), the renderer before the device.
struct Viewer {
    swapchain: Option<Swapchain>,
    surface: Option<Arc<Surface>>,
    window: Option<Arc<Window>>,
    renderer: Renderer,
    device: Arc<Device>,
    scene_grid: mres_format::Grid,
    cluster_count: u32,
    start: FlyCamera,
    fly: FlyCamera,
    tau: f32,
    mode: u32,
    keys: HashSet<KeyCode>,
    looking: bool,
    captured: bool,
    swapchain_stale: bool,
    screenshot_now: bool,
    frames: u32,
    last_frame_time: Option<Instant>,
    title_time: Instant,
    title_frames: u32,
    last: Option<Frame>,
    screenshots: Vec<PathBuf>,
    error: Option<anyhow::Error>,
    options: ViewerOptions,
}

fn mode_name(mode: u32) -> &'static str {
    match mode {
        MODE_SHADED => "shaded",
        MODE_CLUSTER => "cluster",
        MODE_GROUP => "group",
        MODE_LEVEL => "level",
        MODE_ERROR => "error",
        _ => "?",
    }
}

impl Viewer {
    fn fail(&mut self, event_loop: &ActiveEventLoop, error: anyhow::Error) {
        if self.error.is_none() {
            self.error = Some(error);
        }
        event_loop.exit();
    }

    fn movement(&self) -> Movement {
        let axis = |plus: &[KeyCode], minus: &[KeyCode]| {
            let held = |keys: &[KeyCode]| keys.iter().any(|k| self.keys.contains(k));
            held(plus) as i32 as f32 - held(minus) as i32 as f32
        };
        Movement {
            forward: axis(&[KeyCode::KeyW], &[KeyCode::KeyS]),
            right: axis(&[KeyCode::KeyD], &[KeyCode::KeyA]),
            up: axis(&[KeyCode::KeyE, KeyCode::Space], &[KeyCode::KeyQ, KeyCode::ControlLeft, KeyCode::ControlRight]),
            fast: self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight),
        }
    }

    fn set_capture(&mut self, on: bool) {
        let Some(window) = &self.window else { return };
        if on {
            // Locked where the platform has it (Wayland, macOS), else confined (X11, Windows);
            // look uses raw device motion either way.
            let grabbed = window
                .set_cursor_grab(CursorGrabMode::Locked)
                .or_else(|_| window.set_cursor_grab(CursorGrabMode::Confined));
            if grabbed.is_ok() {
                window.set_cursor_visible(false);
            }
        } else {
            let _ = window.set_cursor_grab(CursorGrabMode::None);
            window.set_cursor_visible(true);
        }
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, code: KeyCode) {
        match code {
            KeyCode::Escape => event_loop.exit(),
            KeyCode::Digit1 | KeyCode::Numpad1 => self.mode = MODE_SHADED,
            KeyCode::Digit2 | KeyCode::Numpad2 => self.mode = MODE_CLUSTER,
            KeyCode::Digit3 | KeyCode::Numpad3 => self.mode = MODE_GROUP,
            KeyCode::Digit4 | KeyCode::Numpad4 => self.mode = MODE_LEVEL,
            KeyCode::Digit5 | KeyCode::Numpad5 => self.mode = MODE_ERROR,
            KeyCode::Equal | KeyCode::NumpadAdd => self.scale_tau(TAU_STEP),
            KeyCode::Minus | KeyCode::NumpadSubtract => self.scale_tau(1.0 / TAU_STEP),
            KeyCode::KeyR => self.fly = self.start,
            KeyCode::KeyP => self.screenshot_now = true,
            KeyCode::Tab => {
                self.captured = !self.captured;
                self.set_capture(self.captured);
            }
            _ => {}
        }
    }

    fn scale_tau(&mut self, factor: f32) {
        self.tau = (self.tau * factor).clamp(TAU_RANGE.0, TAU_RANGE.1);
    }

    fn create_window(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let (w, h) = self.options.size;
        let attributes = Window::default_attributes()
            .with_title(format!("preview — {}", self.options.label))
            .with_inner_size(PhysicalSize::new(w, h));
        let window = Arc::new(event_loop.create_window(attributes).context("cannot create the window")?);
        self.surface = Some(Surface::new(&self.device, window.clone())?);
        self.window = Some(window);
        self.swapchain_stale = true;
        Ok(())
    }

    /// Recreates the swapchain at the window's size; false while the window has no area.
    fn ensure_swapchain(&mut self) -> Result<bool> {
        let (Some(window), Some(surface)) = (&self.window, &self.surface) else { return Ok(false) };
        let size = window.inner_size();
        if size.width == 0 || size.height == 0 {
            return Ok(false);
        }
        if self.swapchain_stale || self.swapchain.is_none() {
            let fresh = Swapchain::new(&self.device, surface, size.width, size.height, self.swapchain.as_ref())?;
            // The old one waits for the queue to go idle before it is destroyed.
            self.swapchain = Some(fresh);
            self.swapchain_stale = false;
        }
        Ok(true)
    }

    fn frame(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let now = Instant::now();
        let seconds = self.last_frame_time.map_or(0.0, |t| (now - t).as_secs_f32().min(0.25));
        self.last_frame_time = Some(now);
        let movement = self.movement();
        self.fly.fly(movement, seconds);
        if !self.ensure_swapchain()? {
            return Ok(());
        }
        let Some(swapchain) = &self.swapchain else { return Ok(()) };
        let Some(image) = swapchain.acquire()? else {
            self.swapchain_stale = true;
            return Ok(());
        };
        let last_frame = self.options.frames.is_some_and(|n| self.frames + 1 >= n);
        let screenshot_path = if self.screenshot_now {
            Some(
                self.options
                    .screenshot
                    .clone()
                    .unwrap_or_else(|| PathBuf::from(format!("preview-{:05}.png", self.frames))),
            )
        } else if last_frame {
            self.options.screenshot.clone()
        } else {
            None
        };
        let extent = swapchain.extent;
        let camera: Camera = self.fly.camera(extent.width, extent.height);
        let mut view = camera.gpu_view(self.tau, &self.scene_grid, self.cluster_count, FLAG_FRUSTUM_CULL);
        view.mode = self.mode;
        // From here on the acquired image must be submitted (its semaphore is signalled).
        let mut frame = self.renderer.render_to_swapchain(&view, swapchain, &image, screenshot_path.is_some())?;
        if !swapchain.present(&image)? {
            self.swapchain_stale = true;
        }
        if let Some(path) = screenshot_path {
            write_png(&path, frame.width, frame.height, &frame.rgba)?;
            println!(
                "screenshot: {} ({}x{}, eye {:?}, tau {} px, mode {})",
                path.display(),
                frame.width,
                frame.height,
                camera.eye,
                self.tau,
                mode_name(self.mode)
            );
            self.screenshots.push(path);
            self.screenshot_now = false;
        }
        frame.rgba = Vec::new();
        self.frames += 1;
        self.title_frames += 1;
        let since = now - self.title_time;
        if since >= TITLE_INTERVAL || last_frame {
            let fps = self.title_frames as f64 / since.as_secs_f64().max(1e-9);
            let gpu = frame
                .times
                .map(|t| {
                    format!(
                        "GPU {:.2} ms (select {:.2}, expand {:.2}, draw {:.2})",
                        t.select_ms + t.expand_ms + t.draw_ms,
                        t.select_ms,
                        t.expand_ms,
                        t.draw_ms
                    )
                })
                .unwrap_or_else(|| "no GPU timestamps".into());
            let title = format!(
                "preview — {} — {} — τ {:.3} px — {} clusters, {} triangles — {gpu} — {fps:.0} fps",
                self.options.label,
                mode_name(self.mode),
                self.tau,
                frame.clusters,
                frame.triangles
            );
            if let Some(window) = &self.window {
                window.set_title(&title);
            }
            if last_frame {
                println!("window: {} frames at {}x{}; last frame: {title}", self.frames, frame.width, frame.height);
            }
            self.title_time = now;
            self.title_frames = 0;
        }
        self.last = Some(frame);
        if last_frame {
            event_loop.exit();
        }
        Ok(())
    }
}

impl ApplicationHandler for Viewer {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_none() {
            if let Err(e) = self.create_window(event_loop) {
                self.fail(event_loop, e);
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(_) | WindowEvent::ScaleFactorChanged { .. } => self.swapchain_stale = true,
            WindowEvent::KeyboardInput { event, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else { return };
                match event.state {
                    ElementState::Pressed => {
                        if !event.repeat {
                            self.key(event_loop, code);
                        }
                        self.keys.insert(code);
                    }
                    ElementState::Released => {
                        self.keys.remove(&code);
                    }
                }
            }
            WindowEvent::Focused(false) => self.keys.clear(),
            WindowEvent::MouseInput { state, button: MouseButton::Right, .. } => {
                self.looking = state == ElementState::Pressed;
                if !self.captured {
                    self.set_capture(self.looking);
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.scale_tau(TAU_STEP.powf(notches));
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.frame(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            _ => {}
        }
    }

    fn device_event(&mut self, _event_loop: &ActiveEventLoop, _id: DeviceId, event: DeviceEvent) {
        if let DeviceEvent::MouseMotion { delta: (dx, dy) } = event {
            if self.looking || self.captured {
                self.fly.look(dx as f32, dy as f32);
            }
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(window) = &self.window {
            window.request_redraw();
        }
    }
}
