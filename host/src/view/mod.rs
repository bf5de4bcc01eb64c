//! `slicelight view`: a window on a scene, rendered by the same passes as
//! `render`, on the same backends.
//!
//! Two threads. The window's (winit's event loop) handles input, watches the
//! scene file and presents; it never waits on a render. The render thread
//! (`worker`) builds the scene for the newest view and renders it one
//! sub-pixel sample at a time, so a moving view shows 1 sample per pixel at
//! once and a still one converges to `--spp` samples: the same image, bit
//! for bit, as `render --spp N` (`render::mean_image` does both sums).
//!
//! The window shows the image through a wgpu surface on the rendering
//! device (the GPU backend) or a software framebuffer (the CPU backend, or a
//! device whose surface cannot be made): `present`.

pub mod overlay;
pub mod present;
pub mod state;
pub mod worker;

use crate::passes::PASSES;
use crate::render::{Backend, BackendChoice, RenderStats};
use crate::scene::{self, SceneData, SceneFile};
use anyhow::{anyhow, Context as _, Result};
use glam::Vec3;
use state::ViewState;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

/// What `slicelight view` was asked.
pub struct Options {
    pub scene: PathBuf,
    pub backend: BackendChoice,
    /// Samples per pixel a still view accumulates.
    pub samples: u32,
    /// Window (and render) size; `None`: the scene's resolution.
    pub size: Option<[u32; 2]>,
    /// Where `S` writes its PNG and EXR.
    pub output_dir: PathBuf,
}

/// How often the scene file's modification time is read.
const WATCH_INTERVAL: Duration = Duration::from_millis(250);
/// How long a notice stays on the panel.
const NOTICE_SECONDS: f64 = 6.0;
/// Radians of orbit per pixel of mouse drag.
const ORBIT_PER_PIXEL: f32 = 0.005;

/// The keys, as the panel's help lists them.
const HELP: &[&str] = &[
    "drag: orbit   wheel: dolly   arrows, Q E: fly (or move the light)",
    "Tab: select a light   J L: sun azimuth   I K: sun height",
    "[ ]: density   - =: planes   , .: sub-planes   1-9: pass on/off",
    "Space: play/pause   B N: -/+ 1 s   Home: t = 0",
    "S: save PNG + EXR   C: print camera   R: reset view   H: panel   Esc: quit",
];

/// Opens the window and runs until it is closed. The scene is loaded
/// first: a scene that does not load is an error before any window opens.
pub fn run(opts: Options) -> Result<()> {
    let base = scene::load(&opts.scene)?;
    let size = opts.size.unwrap_or([base.width(), base.height()]);
    if !opts.output_dir.is_dir() {
        return Err(anyhow!("--output-dir: {} is not a folder", opts.output_dir.display()));
    }
    let event_loop = EventLoop::<()>::with_user_event()
        .build()
        .context("cannot open a window: no display (set DISPLAY, or run under Xvfb)")?;
    let backend = Backend::open(opts.backend)?;
    eprintln!("backend: {} on {}", backend.name(), backend.device());
    let handles = match &backend {
        Backend::Gpu(ctx) => Some(ctx.handles()),
        Backend::Cpu => None,
    };
    let proxy = event_loop.create_proxy();
    let (to_worker, requests) = channel();
    let (replies, from_worker) = channel();
    let view = ViewState::of(&base.source.file, size, opts.samples);
    let file = base.source.file.clone();
    let path = opts.scene.clone();
    std::thread::Builder::new()
        .name("render".into())
        .spawn(move || {
            worker::run(path, base, backend, requests, replies, move || {
                let _ = proxy.send_event(());
            })
        })
        .context("cannot start the render thread")?;
    let mut app = App::new(opts, file, view, to_worker, from_worker, handles);
    app.show();
    event_loop.run_app(&mut app).context("the window's event loop")?;
    app.finish();
    match app.fatal.take() {
        Some(e) => Err(anyhow!(e)),
        None => Ok(()),
    }
}

/// The window's side.
struct App {
    opts: Options,
    /// The scene file as last loaded (the view's defaults).
    file: SceneFile,
    view: ViewState,
    generation: u64,
    to_worker: Sender<worker::Request>,
    from_worker: Receiver<worker::Reply>,
    window: Option<Arc<Window>>,
    presenter: Option<present::Presenter>,
    /// The rendering device's handles, for a wgpu surface (GPU backend).
    handles: Option<(wgpu::Instance, wgpu::Adapter, wgpu::Device, wgpu::Queue)>,
    /// The window's pixels: the image, then the panel over it.
    canvas: Vec<u32>,
    frame: Option<Box<worker::Frame>>,
    /// Frames presented and when (the frame rate over the last second).
    presented: Vec<Instant>,
    /// When the input behind each generation came (latency to its first image).
    input_at: Option<(u64, Instant)>,
    latencies: Vec<f64>,
    error: Option<String>,
    notice: Option<(String, Instant)>,
    panel: u8,
    playing: Option<Instant>,
    drag: Option<(f64, f64)>,
    cursor: (f64, f64),
    watched: Option<SystemTime>,
    next_watch: Instant,
    /// An error that ends the viewer with a non-zero exit (no render thread).
    fatal: Option<String>,
    /// Presentations that failed in a row.
    surface_failures: u32,
}

impl App {
    fn new(
        opts: Options,
        file: SceneFile,
        view: ViewState,
        to_worker: Sender<worker::Request>,
        from_worker: Receiver<worker::Reply>,
        handles: Option<(wgpu::Instance, wgpu::Adapter, wgpu::Device, wgpu::Queue)>,
    ) -> App {
        let watched = modified(&opts.scene);
        App {
            opts,
            file,
            view,
            generation: 0,
            to_worker,
            from_worker,
            window: None,
            presenter: None,
            handles,
            canvas: Vec::new(),
            frame: None,
            presented: Vec::new(),
            input_at: None,
            latencies: Vec::new(),
            error: None,
            notice: None,
            panel: 1,
            playing: None,
            drag: None,
            cursor: (0.0, 0.0),
            watched,
            next_watch: Instant::now() + WATCH_INTERVAL,
            fatal: None,
            surface_failures: 0,
        }
    }

    /// Asks the render thread for the current view.
    fn show(&mut self) {
        self.generation += 1;
        let view = Box::new(self.view.clone());
        let _ = self.to_worker.send(worker::Request::Show { generation: self.generation, view });
    }

    /// The view changed by the user: show it, and time it.
    fn changed(&mut self) {
        self.show();
        if self.input_at.is_none() {
            self.input_at = Some((self.generation, Instant::now()));
        }
    }

    fn redraw(&self) {
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }

    /// Everything the render thread has sent.
    fn receive(&mut self) {
        let mut got = false;
        loop {
            let reply = match self.from_worker.try_recv() {
                Ok(r) => {
                    got = true;
                    r
                }
                Err(std::sync::mpsc::TryRecvError::Empty) => break,
                Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                    self.fatal.get_or_insert_with(|| "the render thread stopped".into());
                    break;
                }
            };
            match reply {
                worker::Reply::Frame(f) => {
                    if f.generation != self.generation {
                        continue; // superseded while it rendered
                    }
                    if f.samples == f.target {
                        crate::output::say(&format!(
                            "converged: {} samples per pixel, {}x{}, t = {:.3} s, {:.3} s",
                            f.target,
                            f.width,
                            f.height,
                            self.file.time.seconds + f.time,
                            f.seconds
                        ));
                    }
                    if f.samples == 1 {
                        self.error = None;
                    }
                    self.frame = Some(f);
                    if let Some(start) = self.playing {
                        // Playing: the next frame at the wall clock's instant.
                        self.view.time += start.elapsed().as_secs_f64();
                        self.playing = Some(Instant::now());
                        self.show();
                    }
                }
                worker::Reply::Loaded(file) => {
                    let camera_moved = file.camera != self.file.camera;
                    let size = self.view.size;
                    let mut fresh = ViewState::of(&file, size, self.opts.samples);
                    if !camera_moved {
                        // Keep where the user has moved to; the file's other edits show.
                        fresh.position = self.view.position;
                        fresh.look_at = self.view.look_at;
                        fresh.up = self.view.up;
                    }
                    fresh.disabled = std::mem::take(&mut self.view.disabled);
                    fresh.time = self.view.time;
                    self.view = fresh;
                    self.file = *file;
                    self.error = None;
                    self.notice = Some(("scene file reloaded".into(), Instant::now()));
                    self.show();
                }
                worker::Reply::Error(e) => {
                    eprintln!("slicelight: error: {e}");
                    if self.frame.is_none() && self.generation == 1 {
                        // The very first view failed (no device, say): nothing to keep on screen.
                        self.fatal = Some(e.clone());
                    }
                    self.error = Some(e);
                }
                worker::Reply::Notice(n) => {
                    eprintln!("{n}");
                    self.notice = Some((n, Instant::now()));
                }
            }
        }
        if got {
            self.redraw();
        }
    }

    /// The passes that draw a layer, in the order the keys 1-9 toggle them.
    fn toggleable(&self) -> Vec<&'static str> {
        let Some(f) = &self.frame else { return Vec::new() };
        f.stats
            .passes
            .iter()
            .filter(|p| p.ran || p.reason == crate::render::TURNED_OFF)
            .filter(|p| PASSES.iter().any(|q| q.name() == p.name && q.radiance_layer().is_some()))
            .map(|p| p.name)
            .collect()
    }

    fn key(&mut self, key: &Key, event_loop: &ActiveEventLoop) {
        let shafts = self.file.shafts;
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::ArrowUp) => self.view.fly(Vec3::Z),
            Key::Named(NamedKey::ArrowDown) => self.view.fly(-Vec3::Z),
            Key::Named(NamedKey::ArrowLeft) => self.view.fly(-Vec3::X),
            Key::Named(NamedKey::ArrowRight) => self.view.fly(Vec3::X),
            Key::Named(NamedKey::Tab) => {
                self.view.select_next_light();
                self.redraw();
                return;
            }
            Key::Named(NamedKey::Space) => {
                self.playing = match self.playing {
                    Some(_) => None,
                    None => Some(Instant::now()),
                };
            }
            Key::Named(NamedKey::Home) => self.view.time = 0.0,
            Key::Character(c) => match c.as_str() {
                "e" | "E" => self.view.fly(Vec3::Y),
                "q" | "Q" => self.view.fly(-Vec3::Y),
                "j" | "J" => self.view.sun_turn[1] -= 5.0,
                "l" | "L" => self.view.sun_turn[1] += 5.0,
                "i" | "I" => self.view.sun_turn[0] -= 2.0,
                "k" | "K" => self.view.sun_turn[0] += 2.0,
                "b" | "B" => self.view.time -= 1.0,
                "n" | "N" => self.view.time += 1.0,
                "[" => self.view.density *= 0.8,
                "]" => self.view.density *= 1.25,
                "-" => self.view.scale_planes(shafts.planes, false),
                "=" | "+" => self.view.scale_planes(shafts.planes, true),
                "," => self.view.step_subplanes(shafts.subplanes, false),
                "." => self.view.step_subplanes(shafts.subplanes, true),
                "r" | "R" => {
                    let mut fresh = ViewState::of(&self.file, self.view.size, self.opts.samples);
                    fresh.time = self.view.time;
                    self.view = fresh;
                }
                "h" | "H" => {
                    self.panel = (self.panel + 1) % 3;
                    self.redraw();
                    return;
                }
                "c" | "C" => {
                    crate::output::say(&self.view.camera_toml(&self.file));
                    return;
                }
                "s" | "S" => {
                    self.save();
                    return;
                }
                digit if digit.len() == 1 && ('1'..='9').contains(&digit.chars().next().unwrap_or(' ')) => {
                    let k = digit.parse::<usize>().unwrap_or(1) - 1;
                    match self.toggleable().get(k) {
                        Some(name) => self.view.toggle_pass(name),
                        None => return,
                    }
                }
                _ => return,
            },
            _ => return,
        }
        self.changed();
    }

    /// `S`: the current image as `<scene>-view-NNN.png` and `.exr` in the
    /// output folder, the first number not taken.
    fn save(&mut self) {
        let stem = self.opts.scene.file_stem().and_then(|s| s.to_str()).unwrap_or("view").to_string();
        let dir = &self.opts.output_dir;
        let free = (0..100_000)
            .find(|n| !["png", "exr"].iter().any(|ext| dir.join(format!("{stem}-view-{n:03}.{ext}")).exists()));
        let Some(n) = free else {
            self.error = Some(format!("{}: no free file name for the screenshot", dir.display()));
            return;
        };
        let paths = ["png", "exr"].iter().map(|ext| dir.join(format!("{stem}-view-{n:03}.{ext}"))).collect();
        let _ = self.to_worker.send(worker::Request::Save(paths));
    }

    /// The panel's lines.
    fn panel_lines(&self) -> Vec<(String, u32)> {
        use overlay::{RED, WHITE, YELLOW};
        let mut lines = Vec::new();
        let now = Instant::now();
        let fps = self.presented.iter().filter(|t| now.duration_since(**t) < Duration::from_secs(1)).count();
        match &self.frame {
            Some(f) => {
                lines.push((format!("{} {}x{}", f.backend, f.width, f.height), WHITE));
                lines.push((
                    format!(
                        "samples {}/{}  last sample {:.1} ms  view {:.1} ms  {fps} fps",
                        f.samples,
                        f.target,
                        1e3 * f.stats.total_seconds,
                        1e3 * f.seconds
                    ),
                    WHITE,
                ));
                lines.extend(pass_lines(&f.stats, &self.toggleable()));
            }
            None => lines.push(("rendering the first frame...".into(), WHITE)),
        }
        if let Some(l) = self.latencies.last() {
            lines.push((format!("input to frame {:.1} ms", 1e3 * l), WHITE));
        }
        let v = &self.view;
        lines.push((
            format!(
                "t = {:.2} s{}  sun {:+.0}/{:+.0} deg  density x{:.2}",
                self.file.time.seconds + v.time,
                if self.playing.is_some() { " (playing)" } else { "" },
                v.sun_turn[0],
                v.sun_turn[1],
                v.density
            ),
            WHITE,
        ));
        let moves = match v.selected_light {
            Some(k) => format!("light {k}"),
            None => "camera".into(),
        };
        let shafts = self.frame.as_ref().is_some_and(|f| f.stats.passes.iter().any(|p| p.name == "shafts" && p.ran));
        let planes = match shafts {
            true => format!(
                "planes {}  sub-planes {}  ",
                v.planes.unwrap_or(self.file.shafts.planes),
                v.subplanes.unwrap_or(self.file.shafts.subplanes)
            ),
            false => String::new(),
        };
        lines.push((format!("{planes}keys move: {moves}"), WHITE));
        if self.panel == 2 {
            lines.extend(HELP.iter().map(|h| (h.to_string(), YELLOW)));
        } else {
            lines.push(("H: keys".into(), YELLOW));
        }
        if let Some((n, at)) = &self.notice {
            if at.elapsed().as_secs_f64() < NOTICE_SECONDS {
                lines.push((n.clone(), YELLOW));
            }
        }
        if let Some(e) = &self.error {
            // Long messages wrap at the window's width.
            let per_line = (self.view.size[0] as usize / 8).saturating_sub(2).max(16);
            let chars: Vec<char> = e.chars().collect();
            for chunk in chars.chunks(per_line) {
                lines.push((chunk.iter().collect(), RED));
            }
        }
        lines
    }

    /// Draws the newest image and the panel. A surface that fails (the X
    /// server's shared memory gone, a swapchain lost) is made again from the
    /// window; three failures in a row end the viewer with the error.
    fn present(&mut self) {
        match self.try_present() {
            Ok(()) => self.surface_failures = 0,
            Err(e) => {
                self.surface_failures += 1;
                eprintln!("the window's surface failed ({e:#}); making it again");
                self.presenter = None;
                if self.surface_failures >= 3 {
                    self.fatal = Some(format!("the window's surface failed three times: {e:#}"));
                    return;
                }
                if let Some(w) = self.window.clone() {
                    match self.make_presenter(&w) {
                        Ok(p) => self.presenter = Some(p),
                        Err(e) => self.fatal = Some(format!("{e:#}")),
                    }
                }
                self.redraw();
            }
        }
    }

    /// The device's surface on the GPU backend, else (or if that fails,
    /// with a notice) a software framebuffer.
    fn make_presenter(&mut self, window: &Arc<Window>) -> Result<present::Presenter> {
        if let Some(handles) = self.handles.clone() {
            match present::Presenter::device(window, handles) {
                Ok(p) => return Ok(p),
                Err(e) => {
                    let note = format!("{e:#}; presenting through a software framebuffer");
                    eprintln!("{note}");
                    self.notice = Some((note, Instant::now()));
                    self.handles = None;
                }
            }
        }
        present::Presenter::software(window)
    }

    fn try_present(&mut self) -> Result<()> {
        let lines = if self.panel > 0 { self.panel_lines() } else { Vec::new() };
        let Some(window) = self.window.clone() else { return Ok(()) };
        let size = window.inner_size();
        let (ww, wh) = (size.width as usize, size.height as usize);
        if ww == 0 || wh == 0 {
            return Ok(()); // minimised
        }
        self.canvas.clear();
        self.canvas.resize(ww * wh, 0);
        if let Some(f) = &self.frame {
            // The image at the top left (during a resize it is the old size
            // until the new one renders).
            let (fw, fh) = (f.width as usize, f.height as usize);
            for y in 0..fh.min(wh) {
                let n = fw.min(ww);
                self.canvas[y * ww..y * ww + n].copy_from_slice(&f.pixels[y * fw..y * fw + n]);
            }
        }
        overlay::draw(&mut self.canvas, ww, &lines);
        let Some(presenter) = self.presenter.as_mut() else { return Ok(()) };
        presenter.present(&self.canvas, size.width, size.height)?;
        let now = Instant::now();
        self.presented.retain(|t| now.duration_since(*t) < Duration::from_secs(2));
        self.presented.push(now);
        if let (Some((g, at)), Some(f)) = (self.input_at, &self.frame) {
            if f.generation >= g {
                self.latencies.push(at.elapsed().as_secs_f64());
                self.input_at = None;
            }
        }
        if let Some(f) = &self.frame {
            window.set_title(&format!(
                "slicelight: {}  {}/{} spp  {:.1} ms",
                self.opts.scene.display(),
                f.samples,
                f.target,
                1e3 * f.stats.total_seconds
            ));
        }
        Ok(())
    }

    /// Looks at the scene file's modification time; a change reloads it.
    fn watch(&mut self) {
        if Instant::now() < self.next_watch {
            return;
        }
        self.next_watch = Instant::now() + WATCH_INTERVAL;
        let m = modified(&self.opts.scene);
        if m.is_some() && m != self.watched {
            self.watched = m;
            let _ = self.to_worker.send(worker::Request::Reload);
        }
    }

    /// On exit: the input-to-frame latencies, on stderr.
    fn finish(&mut self) {
        let _ = self.to_worker.send(worker::Request::Quit);
        if !self.latencies.is_empty() {
            let worst = self.latencies.iter().copied().fold(0.0, f64::max);
            eprintln!(
                "input to frame: median {:.1} ms, worst {:.1} ms over {} changes",
                1e3 * crate::bench::median(self.latencies.clone()),
                1e3 * worst,
                self.latencies.len()
            );
        }
    }
}

/// Per-pass lines of the panel: the passes that ran with their times, the
/// toggleable ones numbered.
fn pass_lines(stats: &RenderStats, toggleable: &[&str]) -> Vec<(String, u32)> {
    stats
        .passes
        .iter()
        .filter(|p| p.ran || p.reason == crate::render::TURNED_OFF)
        .map(|p| {
            let key = match toggleable.iter().position(|n| *n == p.name) {
                Some(k) if k < 9 => format!("{} ", k + 1),
                _ => "  ".into(),
            };
            let text = if p.kept {
                format!("{key}{:<20}     kept", p.name)
            } else if p.ran {
                format!("{key}{:<20} {:>8.2} ms", p.name, 1e3 * p.seconds)
            } else {
                format!("{key}{:<20}      off", p.name)
            };
            (text, if p.ran { overlay::WHITE } else { overlay::YELLOW })
        })
        .collect()
}

fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

impl ApplicationHandler<()> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let [w, h] = self.view.size;
        let attrs = Window::default_attributes()
            .with_title(format!("slicelight: {}", self.opts.scene.display()))
            .with_inner_size(PhysicalSize::new(w, h));
        let made = event_loop.create_window(attrs).map_err(|e| anyhow!("cannot open a window: {e}")).and_then(|w| {
            let w = Arc::new(w);
            let presenter = self.make_presenter(&w)?;
            Ok((w, presenter))
        });
        match made {
            Ok((w, p)) => {
                eprintln!("window: presenting through {}", p.describe());
                self.window = Some(w);
                self.presenter = Some(p);
            }
            Err(e) => {
                self.fatal = Some(format!("{e:#}"));
                event_loop.exit();
            }
        }
    }

    fn user_event(&mut self, event_loop: &ActiveEventLoop, _: ()) {
        self.receive();
        if self.fatal.is_some() {
            event_loop.exit();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if size.width > 0 && size.height > 0 && [size.width, size.height] != self.view.size {
                    self.view.size = [size.width, size.height];
                    self.changed();
                }
                self.redraw();
            }
            WindowEvent::RedrawRequested => {
                self.present();
                if self.fatal.is_some() {
                    event_loop.exit();
                }
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(&event.logical_key, event_loop)
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                self.drag = (state == ElementState::Pressed).then_some(self.cursor);
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                if let Some((x0, y0)) = self.drag {
                    let (dx, dy) = (position.x - x0, position.y - y0);
                    self.drag = Some(self.cursor);
                    self.view.orbit(-ORBIT_PER_PIXEL * dx as f32, ORBIT_PER_PIXEL * dy as f32);
                    self.changed();
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.view.dolly(0.1 * lines);
                self.changed();
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        self.watch();
        self.receive();
        if self.fatal.is_some() {
            event_loop.exit();
            return;
        }
        event_loop.set_control_flow(ControlFlow::WaitUntil(self.next_watch));
    }
}

/// `slicelight view --headless N`: the window's frame loop without a
/// window: `frames` views, each orbiting the last by a degree, each asked
/// for as soon as the one before has its first image (1 sample per pixel),
/// as a user dragging the mouse would. Returns each view's seconds from
/// request to image and its last render's statistics.
pub fn headless(
    scene: &Path,
    base: SceneData,
    choice: BackendChoice,
    size: [u32; 2],
    frames: usize,
) -> Result<Vec<(f64, RenderStats)>> {
    let (to_worker, requests) = channel();
    let (replies, from_worker) = channel();
    let mut view = ViewState::of(&base.source.file, size, 1);
    let path = scene.to_path_buf();
    let backend = Backend::open(choice)?;
    let thread = std::thread::spawn(move || worker::run(path, base, backend, requests, replies, || {}));
    let mut out = Vec::with_capacity(frames);
    for generation in 1..=frames as u64 {
        view.orbit(1f32.to_radians(), 0.0);
        to_worker
            .send(worker::Request::Show { generation, view: Box::new(view.clone()) })
            .map_err(|_| anyhow!("the render thread stopped"))?;
        loop {
            match from_worker.recv().map_err(|_| anyhow!("the render thread stopped"))? {
                worker::Reply::Frame(f) if f.generation == generation => {
                    out.push((f.seconds, f.stats));
                    break;
                }
                worker::Reply::Error(e) => return Err(anyhow!(e)),
                _ => {}
            }
        }
    }
    let _ = to_worker.send(worker::Request::Quit);
    let _ = thread.join();
    Ok(out)
}
