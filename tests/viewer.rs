//! `slicelight view` in a real window: each test starts its own X server
//! (Xvfb), opens the viewer on a shipped scene, drives it with real key and
//! mouse events (xdotool, through the XTEST extension) and reads the window
//! back (xwd). Xvfb, xdotool and xwd are required, as the Vulkan device is
//! for the equivalence tests: `scripts/setup.sh` installs them, and a
//! machine without them fails here rather than skipping.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_slicelight");
/// Fig. 6 at 160 x 120: fast on both backends, and its hard-edged shaft
/// makes a moved camera plainly visible.
const SCENE: &str = "../scenes/fig6_sphere.toml";
const SIZE: [u32; 2] = [160, 120];
/// How long a window may take to show its first converged view (lavapipe
/// builds its pipelines first: seconds on 2 cores).
const START: Duration = Duration::from_secs(180);

fn need(tool: &str) {
    let found = Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(found, "the viewer tests need {tool} (scripts/setup.sh installs xvfb, xdotool and x11-apps)");
}

/// An X server of the test's own, stopped when dropped.
struct Display {
    server: Child,
    name: String,
}

impl Display {
    fn start() -> Display {
        for tool in ["Xvfb", "xdotool", "xwd"] {
            need(tool);
        }
        // Xvfb picks a free display number itself and writes it on the
        // given descriptor (stdout here) once it listens: no race between
        // tests started at once.
        let mut server = Command::new("Xvfb")
            .args(["-displayfd", "1", "-screen", "0", "800x600x24", "-nolisten", "tcp"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb starts");
        let mut line = String::new();
        let read = BufReader::new(server.stdout.take().expect("piped")).read_line(&mut line);
        match (read, line.trim().parse::<u32>()) {
            (Ok(_), Ok(n)) => Display { server, name: format!(":{n}") },
            _ => {
                let _ = server.kill();
                let _ = server.wait();
                panic!("Xvfb did not start (it printed {line:?})");
            }
        }
    }

    fn xdotool(&self, args: &[&str]) -> String {
        let out = Command::new("xdotool").args(args).env("DISPLAY", &self.name).output().expect("xdotool runs");
        assert!(out.status.success(), "xdotool {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    }
}

impl Drop for Display {
    fn drop(&mut self) {
        // SIGTERM: Xvfb removes its socket and lock file (SIGKILL leaves them).
        let _ = Command::new("kill").arg(self.server.id().to_string()).status();
        let _ = self.server.wait();
    }
}

/// A running viewer: its stdout and stderr lines as they come.
struct Viewer<'a> {
    display: &'a Display,
    child: Child,
    lines: Receiver<(bool, String)>,
    /// Every line so far (stderr ones marked `true`).
    seen: Vec<(bool, String)>,
    window: String,
}

impl<'a> Viewer<'a> {
    fn start(display: &'a Display, scene: &Path, backend: &str, out: &Path) -> Viewer<'a> {
        let mut child = Command::new(BIN)
            .arg("view")
            .arg(scene)
            .args(["--backend", backend, "--spp", "4", "--size", &format!("{}x{}", SIZE[0], SIZE[1])])
            .arg("--output-dir")
            .arg(out)
            .env("DISPLAY", &display.name)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the viewer starts");
        let (tx, lines) = channel();
        for (is_err, stream) in [
            (false, Box::new(child.stdout.take().expect("piped")) as Box<dyn std::io::Read + Send>),
            (true, Box::new(child.stderr.take().expect("piped"))),
        ] {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    let _ = tx.send((is_err, line));
                }
            });
        }
        let mut v = Viewer { display, child, lines, seen: Vec::new(), window: String::new() };
        v.wait_for("converged:", START);
        let ids = display.xdotool(&["search", "--sync", "--name", "^slicelight"]);
        v.window = ids.lines().next().expect("a window").trim().to_string();
        // Keys go to the focused window (no window manager: focus it here).
        display.xdotool(&["windowfocus", "--sync", &v.window]);
        display.xdotool(&["mousemove", "--window", &v.window, "80", "60"]);
        v
    }

    /// The first line seen so far that starts with `prefix`.
    fn line_starting(&self, prefix: &str) -> Option<String> {
        self.seen.iter().find(|(_, l)| l.starts_with(prefix)).map(|(_, l)| l.clone())
    }

    /// Waits for a line containing `text`; returns it.
    fn wait_for(&mut self, text: &str, within: Duration) -> String {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    self.seen.push(line.clone());
                    if line.1.contains(text) {
                        return line.1;
                    }
                }
                Err(_) => panic!("no line with {text:?} within {within:?}; the viewer said: {:#?}", self.seen),
            }
        }
    }

    fn key(&self, key: &str) {
        self.display.xdotool(&["key", key]);
    }

    /// Lines from now until `text` shows (the camera `C` prints).
    fn lines_until(&mut self, text: &str) -> Vec<String> {
        let start = self.seen.len();
        self.wait_for(text, Duration::from_secs(30));
        self.seen[start..].iter().filter(|(e, _)| !e).map(|(_, l)| l.clone()).collect()
    }

    /// The window's pixels now, from the X server (xwd).
    fn screenshot(&self) -> (u32, u32, Vec<[u8; 3]>) {
        let out = Command::new("xwd")
            .args(["-id", &self.window, "-silent"])
            .env("DISPLAY", &self.display.name)
            .output()
            .expect("xwd runs");
        assert!(out.status.success(), "xwd: {}", String::from_utf8_lossy(&out.stderr));
        parse_xwd(&out.stdout)
    }

    /// Waits until the window shows `expected` (presentation follows a key
    /// by a frame); returns the last screenshot.
    fn screenshot_matching(&self, expected: &[[u8; 3]]) -> Vec<[u8; 3]> {
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            let (w, h, px) = self.screenshot();
            assert_eq!([w, h], SIZE, "the window is the size asked for");
            if px == expected || Instant::now() > deadline {
                return px;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Escape, and the exit status.
    fn quit(mut self) -> (std::process::ExitStatus, Vec<(bool, String)>) {
        self.key("Escape");
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some(status) = self.child.try_wait().expect("the viewer's status") {
                while let Ok(line) = self.lines.recv_timeout(Duration::from_millis(200)) {
                    self.seen.push(line);
                }
                return (status, self.seen.clone());
            }
            assert!(Instant::now() < deadline, "the viewer did not exit after Escape: {:#?}", self.seen);
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Viewer<'_> {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An XWD file (what `xwd` writes: a big-endian header, the window's name,
/// a colour map, then the pixels) as rgb rows. Only the TrueColor formats
/// Xvfb's 24-bit screens give are read.
fn parse_xwd(bytes: &[u8]) -> (u32, u32, Vec<[u8; 3]>) {
    let field = |i: usize| u32::from_be_bytes(bytes[4 * i..4 * i + 4].try_into().expect("4 bytes"));
    let (header, format, width, height) = (field(0) as usize, field(2), field(4), field(5));
    let (byte_order, bits_per_pixel, bytes_per_line) = (field(7), field(11), field(12) as usize);
    let (red, green, blue, colours) = (field(14), field(15), field(16), field(19) as usize);
    assert_eq!(format, 2, "ZPixmap");
    assert_eq!(bits_per_pixel, 32, "32 bits per pixel (a 24-bit screen)");
    let data = &bytes[header + 12 * colours..];
    let channel = |p: u32, mask: u32| ((p & mask) >> mask.trailing_zeros()) as u8;
    let mut out = Vec::with_capacity((width * height) as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let b: [u8; 4] = data[y * bytes_per_line + 4 * x..][..4].try_into().expect("4 bytes");
            let p = if byte_order == 0 { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) };
            out.push([channel(p, red), channel(p, green), channel(p, blue)]);
        }
    }
    (width, height, out)
}

fn read_png(path: &Path) -> Vec<[u8; 3]> {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgb8();
    assert_eq!([img.width(), img.height()], SIZE);
    img.pixels().map(|p| p.0).collect()
}

/// The scene with its `[camera]` lines replaced by `camera` (TOML lines)
/// and the test's resolution: what `render` is given to match the view.
fn scene_with(dir: &Path, name: &str, camera: Option<&str>) -> PathBuf {
    let text = std::fs::read_to_string(SCENE).expect("the scene");
    let mut out = String::new();
    let mut in_camera = false;
    for line in text.lines() {
        if line.starts_with('[') {
            in_camera = line.trim() == "[camera]";
            if in_camera {
                if let Some(c) = camera {
                    out += c;
                    out.push('\n');
                    continue;
                }
            }
        }
        if in_camera && camera.is_some() {
            continue;
        }
        if in_camera && line.starts_with("resolution") {
            out += &format!("resolution = [{}, {}]\n", SIZE[0], SIZE[1]);
            continue;
        }
        out += line;
        out.push('\n');
    }
    let path = dir.join(name);
    std::fs::write(&path, out).expect("written");
    path
}

/// `slicelight render` of `scene` at 4 samples per pixel on the CPU.
fn render(scene: &Path, png: &Path) -> Vec<[u8; 3]> {
    let out = Command::new(BIN)
        .arg("render")
        .arg(scene)
        .args(["--backend", "cpu", "--spp", "4", "-q", "-o"])
        .arg(png)
        .output()
        .expect("render runs");
    assert!(out.status.success(), "render: {}", String::from_utf8_lossy(&out.stderr));
    read_png(png)
}

fn rms_8bit(a: &[[u8; 3]], b: &[[u8; 3]]) -> f64 {
    let sum: f64 = a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |c| (p[c] as f64 - q[c] as f64).powi(2))).sum();
    100.0 * (sum / (3 * a.len()) as f64).sqrt() / 255.0
}

/// The camera `C` printed, as a scene's `[camera]` lines.
fn printed_camera(v: &mut Viewer) -> String {
    v.key("c");
    let lines = v.lines_until("resolution =");
    let start = lines.iter().rposition(|l| l == "[camera]").expect("a [camera] line");
    lines[start..].join("\n")
}

fn vec3_of(camera: &str, key: &str) -> [f32; 3] {
    let table: toml::Table = toml::from_str(camera).expect("the printed camera is TOML");
    let v = table["camera"][key].as_array().expect("an array");
    std::array::from_fn(|i| v[i].as_float().or(v[i].as_integer().map(|n| n as f64)).expect("a number") as f32)
}

#[test]
fn the_window_shows_what_render_writes_moves_with_the_keys_and_survives_a_bad_edit() {
    let display = Display::start();
    let dir = tempfile::tempdir().expect("a temporary folder");
    // The viewer watches its own copy of the scene, edited below.
    let watched = scene_with(dir.path(), "watched.toml", None);
    let mut v = Viewer::start(&display, &watched, "cpu", dir.path());
    let window = v.line_starting("window:");
    assert!(window.as_deref().is_some_and(|w| w.contains("software framebuffer")), "{window:?}");

    // `S` writes what `render` writes: the same PNG pixels, exactly (the
    // viewer sums the same samples in the same order: render::mean_image).
    let expected = render(&watched, &dir.path().join("render.png"));
    v.key("s");
    v.wait_for("wrote", Duration::from_secs(30));
    let saved = read_png(&dir.path().join("watched-view-000.png"));
    assert!(saved == expected, "S's PNG differs from render's: {:.3} % RMS", rms_8bit(&saved, &expected));
    assert!(dir.path().join("watched-view-000.exr").exists(), "S also writes the EXR");

    // The window itself, read back by the X server with the panel hidden
    // (H twice: keys, then off), shows the same pixels.
    v.key("h");
    v.key("h");
    let shown = v.screenshot_matching(&expected);
    assert!(shown == expected, "the window differs from render's PNG: {:.3} % RMS", rms_8bit(&shown, &expected));
    // With the panel, the top-left corner differs and the rest does not.
    v.key("h");
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut differs = 0;
    while differs <= 200 && Instant::now() < deadline {
        let (_, _, with_panel) = v.screenshot();
        differs = with_panel.iter().zip(&expected).filter(|(a, b)| a != b).count();
    }
    assert!(differs > 200, "the panel shows ({differs} pixels differ)");
    v.key("h");
    v.key("h");

    // The camera as it starts, printed with C, is the file's.
    let before = printed_camera(&mut v);
    assert_eq!(vec3_of(&before, "position"), [0.0, 1.8, 8.0]);
    // Up: fly forward by 4 % of the distance to the point looked at.
    v.key("Up");
    v.wait_for("converged:", Duration::from_secs(60));
    let after = printed_camera(&mut v);
    let (p, t) = (vec3_of(&after, "position"), vec3_of(&after, "look_at"));
    assert!((p[2] - (8.0 - 0.04 * 8.0)).abs() < 1e-4 && (t[2] - (-0.32)).abs() < 1e-4, "moved forward: {after}");
    // The new view is what render draws from that camera, and not the old one.
    let moved = render(&scene_with(dir.path(), "moved.toml", Some(&after)), &dir.path().join("moved.png"));
    let shown = v.screenshot_matching(&moved);
    assert!(shown == moved, "after the move: {:.3} % RMS from render's", rms_8bit(&shown, &moved));
    let change = rms_8bit(&moved, &expected);
    assert!(change > 0.5, "moving 0.32 m toward the sphere changes the image ({change:.3} % RMS)");

    // A mouse drag orbits around the point looked at, keeping the distance.
    let w = v.window.clone();
    display.xdotool(&["mousemove", "--window", &w, "60", "60", "mousedown", "1"]);
    display.xdotool(&["mousemove", "--window", &w, "100", "60", "mouseup", "1"]);
    v.wait_for("converged:", Duration::from_secs(60));
    let orbited = printed_camera(&mut v);
    let (q, t2) = (vec3_of(&orbited, "position"), vec3_of(&orbited, "look_at"));
    let dist = |a: [f32; 3], b: [f32; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>().sqrt();
    assert_eq!(t2, t, "an orbit keeps the point looked at");
    assert!((dist(q, t2) - dist(p, t)).abs() < 1e-3, "and the distance: {orbited}");
    assert!((q[0] - p[0]).abs() > 0.1, "and moves the camera sideways: {orbited}");

    // A bad edit: the error, with the field, in the terminal; the viewer
    // runs on and keeps the last good image.
    let shown_before = v.screenshot().2;
    let good = std::fs::read_to_string(&watched).expect("the scene");
    std::fs::write(&watched, good.replace("vfov_deg = 45.0", "vfov_deg = -5.0")).expect("written");
    assert!(good.contains("vfov_deg = 45.0"), "the edit below changes a line the scene has");
    let error = v.wait_for("camera.vfov_deg", Duration::from_secs(30));
    assert!(error.contains("watched.toml"), "the error names the file: {error}");
    std::thread::sleep(Duration::from_millis(500));
    assert!(v.child.try_wait().expect("status").is_none(), "still running after the bad edit");
    let (_, _, still) = v.screenshot();
    let same = still.iter().zip(&shown_before).filter(|(a, b)| a == b).count();
    assert!(same > still.len() / 2, "the last good image stays ({same} of {} pixels)", still.len());
    // The panel (H: on) shows the error in red (overlay::RED, 0xff6060).
    v.key("h");
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut red = 0;
    while red == 0 && Instant::now() < deadline {
        red = v.screenshot().2.iter().filter(|p| **p == [255, 96, 96]).count();
    }
    assert!(red > 50, "the error is on the panel in red ({red} red pixels)");
    v.key("h");
    v.key("h");
    // Fixed again: reloaded.
    std::fs::write(&watched, &good).expect("written");
    v.wait_for("converged:", Duration::from_secs(60));

    // A resized window renders at its new size.
    display.xdotool(&["windowsize", &w, "200", "150"]);
    v.wait_for("converged: 4 samples per pixel, 200x150", Duration::from_secs(60));
    let deadline = Instant::now() + Duration::from_secs(20);
    while v.screenshot().0 != 200 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    let (rw, rh, _) = v.screenshot();
    assert_eq!([rw, rh], [200, 150], "the window took its new size");

    let (status, said) = v.quit();
    assert!(status.success(), "Escape exits 0: {status}");
    let latency = said.iter().find(|(_, l)| l.starts_with("input to frame"));
    assert!(latency.is_some(), "the input-to-frame latency is reported on exit: {said:#?}");
    println!("{}", latency.expect("checked").1);
}

/// The time in a `converged:` line.
fn time_of(line: &str) -> f64 {
    let t = line.split("t = ").nth(1).and_then(|r| r.split(' ').next()).expect("a time");
    t.parse().unwrap_or_else(|e| panic!("{line}: {e}"))
}

#[test]
fn an_animated_scene_scrubs_plays_and_pauses() {
    let display = Display::start();
    let dir = tempfile::tempdir().expect("a temporary folder");
    // The smoke test scene: its fluid runs to the instant shown.
    let mut v = Viewer::start(&display, Path::new("../tests/data/smoke_small.toml"), "cpu", dir.path());
    let first = v.line_starting("converged:").expect("converged");
    assert_eq!(time_of(&first), 0.0, "{first}");
    // What the window must show at 0 s and 1 s: `render` of the scene
    // at that instant (the fluid simulated to it), at the window's size.
    let text = std::fs::read_to_string("../tests/data/smoke_small.toml").expect("the scene");
    let sized = text.replace("resolution = [40, 30]", &format!("resolution = [{}, {}]", SIZE[0], SIZE[1]));
    assert_ne!(sized, text, "the scene's resolution line is as expected");
    let at = |t: f64| {
        let path = dir.path().join(format!("smoke_at_{t}.toml"));
        std::fs::write(&path, format!("{sized}\n[time]\nseconds = {t:?}\n")).expect("written");
        render(&path, &dir.path().join(format!("smoke_at_{t}.png")))
    };
    let (at_start, a_second_on) = (at(0.0), at(1.0));
    let change = rms_8bit(&a_second_on, &at_start);
    assert!(change > 0.1, "a second later the smoke looks different ({change:.3} % RMS)");
    v.key("h");
    v.key("h");
    let shown = v.screenshot_matching(&at_start);
    assert!(shown == at_start, "at 0 s: {:.3} % RMS from render's", rms_8bit(&shown, &at_start));
    // N: one second on.
    v.key("n");
    let later = v.wait_for("converged:", Duration::from_secs(120));
    assert_eq!(time_of(&later), 1.0, "{later}");
    let shown = v.screenshot_matching(&a_second_on);
    assert!(shown == a_second_on, "at 1 s: {:.3} % RMS from render's", rms_8bit(&shown, &a_second_on));
    // Home: back to the start, the same image as before (deterministic).
    v.key("Home");
    let back = v.wait_for("converged:", Duration::from_secs(120));
    assert_eq!(time_of(&back), 0.0, "{back}");
    let again = v.screenshot_matching(&at_start);
    assert!(again == at_start, "the same instant, the same image: {:.3} % RMS", rms_8bit(&again, &at_start));
    // Space plays on the wall clock; Space again pauses and the view converges later on.
    v.key("space");
    std::thread::sleep(Duration::from_millis(1500));
    v.key("space");
    let paused = v.wait_for("converged:", Duration::from_secs(120));
    assert!(time_of(&paused) > 0.5, "played for 1.5 s: {paused}");
    let (status, _) = v.quit();
    assert!(status.success(), "{status}");
}

#[test]
fn on_lavapipe_the_window_shows_the_cpu_render() {
    let display = Display::start();
    let dir = tempfile::tempdir().expect("a temporary folder");
    let scene = scene_with(dir.path(), "lavapipe.toml", None);
    let mut v = Viewer::start(&display, &scene, "gpu", dir.path());
    let device = v.line_starting("backend:");
    assert!(device.as_deref().is_some_and(|d| d.starts_with("backend: gpu on")), "on the device: {device:?}");
    let window = v.line_starting("window:");
    assert!(
        window.as_deref().is_some_and(|w| w.contains("the device's wgpu surface")),
        "presented through the device's surface: {window:?}"
    );
    let cpu = render(&scene, &dir.path().join("cpu.png"));
    v.key("h");
    v.key("h");
    let shown = v.screenshot_matching(&cpu);
    // GPU and CPU kernels differ by fused multiply-adds and flushed
    // denormals (ENVIRONMENT.md): some pixels round to the next 8-bit
    // level. The equivalence tests bound the radiance; here a few levels.
    let rms = rms_8bit(&shown, &cpu);
    let worst = shown.iter().zip(&cpu).flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c]))).max();
    println!("lavapipe window against the CPU render: {rms:.4} % RMS, worst {worst:?} levels");
    assert!(rms < 0.2 && worst <= Some(4), "{rms:.4} % RMS, worst {worst:?} levels of 255");
    v.key("s");
    let wrote = v.wait_for("wrote", Duration::from_secs(30));
    assert!(wrote.contains("4 of 4 samples"), "{wrote}");
    let (status, _) = v.quit();
    assert!(status.success(), "{status}");
}

#[test]
fn without_a_display_the_viewer_says_so_and_fails() {
    let out = Command::new(BIN)
        .args(["view", SCENE, "--backend", "cpu"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "exits non-zero");
    assert!(err.contains("no display"), "says why: {err}");
}

#[test]
fn headless_frame_loop_prints_its_times() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let csv = dir.path().join("views.csv");
    let out = Command::new(BIN)
        .args(["view", SCENE, "--backend", "cpu", "--size", "64x48", "--headless", "5", "--csv"])
        .arg(&csv)
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("5 views at 64x48") && text.contains("median"), "{text}");
    let rows = std::fs::read_to_string(&csv).expect("the CSV");
    assert_eq!(rows.lines().count(), 6, "a header and a row per view: {rows}");
}

/// The memo the viewer renders with (`render::Memo`) hands a `Whole` pass's
/// outputs to the next render only when its inputs are the same: a view
/// rendered after another, with the sky's and the sea's tables taken from
/// the memo, is the image a fresh render gives, bit for bit, on both
/// backends.
#[test]
fn a_view_rendered_with_the_memo_is_the_fresh_render() {
    use slicelight::render::{self, Backend, Memo};
    let base = slicelight::scene::load(Path::new("../scenes/sea_open.toml")).expect("the scene");
    let at = |x: f32| {
        base.reconfigure(move |f| {
            f.camera.resolution = [64, 36];
            f.camera.position[0] += x;
        })
        .expect("valid")
    };
    let (a, b) = (at(0.0), at(5.0));
    let ctx = slicelight::gpu::GpuContext::new().unwrap_or_else(|e| panic!("this test needs a Vulkan device: {e:#}"));
    for backend in [Backend::Cpu, Backend::Gpu(Box::new(ctx))] {
        let mut memo = Memo::default();
        render::render_samples(&a, &backend, 0..1, false, Some(&mut memo)).expect("renders");
        assert_eq!(memo.hits, 0);
        let with = render::render_samples(&b, &backend, 0..1, false, Some(&mut memo)).expect("renders");
        assert!(
            memo.hits >= 4,
            "{}: the sky's and the sea's tables came from the memo ({} hits)",
            backend.name(),
            memo.hits
        );
        let fresh = render::render_samples(&b, &backend, 0..1, false, None).expect("renders");
        assert!(with.image == fresh.image, "{}: the memo changed the image", backend.name());
        // A changed sun changes every table's inputs (the sky's and the
        // sea's parameter blocks hold the sun): nothing is taken.
        let sun = b.reconfigure(move |f| f.sky.as_mut().expect("a sky").sun_zenith_deg += 10.0).expect("valid");
        let hits = memo.hits;
        let moved = render::render_samples(&sun, &backend, 0..1, false, Some(&mut memo)).expect("renders");
        assert_eq!(memo.hits, hits, "{}: no table is reused after the sun moved", backend.name());
        let fresh = render::render_samples(&sun, &backend, 0..1, false, None).expect("renders");
        assert!(moved.image == fresh.image, "{}: after the sun moved", backend.name());
    }
}
