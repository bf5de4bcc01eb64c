//! The viewer's render thread: builds the scene for each new view, renders
//! it one sub-pixel sample at a time (progressive refinement), and hands
//! each improved image to the window. The window's thread never waits on it.

use crate::output;
use crate::passes::Buffer;
use crate::render::{self, Backend, RenderStats};
use crate::scene::{self, SceneData};
use crate::view::state::ViewState;
use anyhow::{anyhow, Result};
use glam::Vec4;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::time::Instant;

/// What the window asks of the render thread.
pub enum Request {
    /// Show this view (`generation` counts the window's changes).
    Show {
        generation: u64,
        view: Box<ViewState>,
    },
    /// Read the scene file again.
    Reload,
    /// Write the current image to these files (`render`'s formats).
    Save(Vec<PathBuf>),
    Quit,
}

/// What the render thread tells the window.
pub enum Reply {
    /// An image of view `generation` after `samples` of `target` samples.
    Frame(Box<Frame>),
    /// The scene file read again (its file, for the window's defaults).
    Loaded(Box<scene::SceneFile>),
    /// A view or a reload that failed; the last good image stays.
    Error(String),
    /// Something to tell the user that is not an error (a backend fallback, a file written).
    Notice(String),
}

pub struct Frame {
    pub generation: u64,
    pub samples: u32,
    pub target: u32,
    pub width: u32,
    pub height: u32,
    /// The tone-mapped image, 0x00RRGGBB per pixel: the PNG's 8 bits.
    pub pixels: Vec<u32>,
    /// The last sample's render (its per-pass times).
    pub stats: RenderStats,
    /// Seconds from the view's request to this image (build + render).
    pub seconds: f64,
    pub backend: String,
    /// The view's clock (s after the scene's `[time] seconds`).
    pub time: f64,
}

/// Something a change to the view does not need rebuilt: the scene as
/// loaded, the view it was last built for, and the samples so far.
struct Accumulation {
    generation: u64,
    data: SceneData,
    /// Per-layer sums over the samples taken (`render::mean_image`'s input).
    sums: Vec<(&'static str, Buffer)>,
    taken: u32,
    requested: Instant,
    time: f64,
}

/// The render thread's loop; returns when asked to quit or the window is gone.
pub fn run(
    path: PathBuf,
    mut base: SceneData,
    mut backend: Backend,
    requests: Receiver<Request>,
    replies: Sender<Reply>,
    wake: impl Fn(),
) {
    let send = |r: Reply| {
        let _ = replies.send(r);
        wake();
    };
    let mut current: Option<Accumulation> = None;
    let mut memo = render::Memo::default();
    loop {
        // Everything the window has asked since the last sample; while
        // there is nothing to render, wait for it.
        let mut pending = Vec::new();
        let busy = current.as_ref().is_some_and(|a| a.taken < a.data.samples_per_pixel());
        if !busy {
            match requests.recv() {
                Ok(r) => pending.push(r),
                Err(_) => return,
            }
        }
        loop {
            match requests.try_recv() {
                Ok(r) => pending.push(r),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return,
            }
        }
        // Only the newest view is built: those before it are superseded.
        let newest = pending.iter().rposition(|r| matches!(r, Request::Show { .. }));
        for (i, request) in pending.into_iter().enumerate() {
            match request {
                Request::Quit => return,
                Request::Show { .. } if Some(i) != newest => {}
                Request::Show { generation, view } => {
                    let requested = Instant::now();
                    match guarded(|| build(&base, &view)) {
                        Ok(data) => {
                            current = Some(Accumulation {
                                generation,
                                data,
                                sums: Vec::new(),
                                taken: 0,
                                requested,
                                time: view.time,
                            })
                        }
                        Err(e) => send(Reply::Error(format!("{}: {e:#}", path.display()))),
                    }
                }
                Request::Reload => match guarded(|| scene::load(&path)) {
                    Ok(data) => {
                        let file = Box::new(data.source.file.clone());
                        base = data;
                        // The window answers with the view to show.
                        send(Reply::Loaded(file));
                    }
                    Err(e) => send(Reply::Error(format!("{e:#}"))),
                },
                Request::Save(paths) => {
                    let done = match &current {
                        Some(a) if a.taken > 0 => save(a, &paths),
                        _ => Err(anyhow!("nothing rendered yet")),
                    };
                    match done {
                        Ok(text) => send(Reply::Notice(text)),
                        Err(e) => send(Reply::Error(format!("saving: {e:#}"))),
                    }
                }
            }
        }
        let Some(acc) = current.as_mut().filter(|a| a.taken < a.data.samples_per_pixel()) else { continue };
        let sample = acc.taken;
        let rendered =
            match guarded(|| render::render_samples(&acc.data, &backend, sample..sample + 1, false, Some(&mut memo))) {
                Ok(r) => r,
                Err(e) if matches!(backend, Backend::Gpu(_)) => {
                    send(Reply::Notice(format!("the device failed ({e:#}); going on with the CPU backend")));
                    backend = Backend::Cpu;
                    memo = render::Memo::default();
                    continue;
                }
                Err(e) => {
                    send(Reply::Error(format!("{}: {e:#}", path.display())));
                    current = None;
                    continue;
                }
            };
        let render::Rendered { layers, stats, .. } = rendered;
        if acc.sums.is_empty() {
            acc.sums = layers;
        } else {
            for ((_, sum), (_, layer)) in acc.sums.iter_mut().zip(&layers) {
                render::add_into(sum.as_mut_slice(), layer.as_slice());
            }
        }
        acc.taken += 1;
        let (image, _) = mean(acc);
        let (width, height) = (acc.data.width(), acc.data.height());
        let rgb = output::tone_map(&image, width, height, acc.data.exposure);
        let pixels = rgb.pixels().map(|p| (u32::from(p[0]) << 16) | (u32::from(p[1]) << 8) | u32::from(p[2])).collect();
        send(Reply::Frame(Box::new(Frame {
            generation: acc.generation,
            samples: acc.taken,
            target: acc.data.samples_per_pixel(),
            width,
            height,
            pixels,
            stats,
            seconds: acc.requested.elapsed().as_secs_f64(),
            backend: format!("{} on {}", backend.name(), backend.device()),
            time: acc.time,
        })));
    }
}

/// `f`, with a panic turned into an error: a bug met by one view is
/// reported on the panel and the viewer goes on with the next view.
fn guarded<T>(f: impl FnOnce() -> Result<T>) -> Result<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic".into());
            Err(anyhow!("internal error (please report it): {what}"))
        }
    }
}

/// The scene of `view`: the loaded scene at the view's instant, its file
/// edited by the view, built and validated as a file is.
pub fn build(base: &SceneData, view: &ViewState) -> Result<SceneData> {
    let t = base.source.file.time.seconds + view.time;
    let view_edit = view.clone();
    // One build: the keyframes at `t` (if any), the scene's edits, the view's.
    let mut data = base.at_time_edited(t, move |f| view_edit.apply(f))?;
    data.disabled_passes = view.disabled.iter().cloned().collect();
    Ok(data)
}

/// The image of the samples taken so far and each pass's layer (the same
/// arithmetic as a render's: `render::mean_image`).
fn mean(acc: &Accumulation) -> (Vec<Vec4>, Vec<(&'static str, Buffer)>) {
    let mut layers = acc.sums.clone();
    (render::mean_image(&mut layers, acc.taken, acc.data.pixel_count() as usize), layers)
}

/// Writes the current image to `paths` (PNG tone-mapped, EXR linear with a
/// layer per pass, as `render` writes them), all or none.
fn save(acc: &Accumulation, paths: &[PathBuf]) -> Result<String> {
    let (image, layers) = mean(acc);
    let slices: Vec<(&str, &[Vec4])> = layers.iter().map(|(n, b)| (*n, b.as_slice::<Vec4>())).collect();
    let shape = (acc.data.width(), acc.data.height(), acc.data.exposure);
    output::write_images(paths, &image, &slices, shape, &[])?;
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    Ok(format!("wrote {} ({} of {} samples)", names.join(", "), acc.taken, acc.data.samples_per_pixel()))
}
