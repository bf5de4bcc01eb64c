//! Writing images: linear OpenEXR or tone-mapped sRGB PNG, chosen by the file
//! extension. A file is written whole or not at all (written to a temporary
//! file beside it, then renamed).

use anyhow::{anyhow, bail, Context, Result};
use glam::Vec4;
use image::{ImageFormat, RgbImage};
use std::io::Write;
use std::path::Path;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Png,
    Exr,
}

/// The format named by the extension of `path`, or an error saying which are known.
pub fn format_of(path: &Path) -> Result<Format> {
    match path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("png") => Ok(Format::Png),
        Some("exr") => Ok(Format::Exr),
        _ => bail!(
            "{}: expected an output file ending in .png (tone-mapped sRGB) or .exr (linear radiance)",
            path.display()
        ),
    }
}

/// sRGB transfer function (IEC 61966-2-1) of a linear value in [0, 1].
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The 8-bit sRGB value of a linear radiance times the exposure, clamped:
/// the tone mapping of the PNG output.
pub fn to_8bit(radiance: f32, exposure: f32) -> u8 {
    let v = (radiance * exposure).clamp(0.0, 1.0);
    (linear_to_srgb(v) * 255.0 + 0.5) as u8
}

pub fn tone_map(pixels: &[Vec4], width: u32, height: u32, exposure: f32) -> RgbImage {
    RgbImage::from_fn(width, height, |x, y| {
        let p = pixels[(y * width + x) as usize];
        image::Rgb([to_8bit(p.x, exposure), to_8bit(p.y, exposure), to_8bit(p.z, exposure)])
    })
}

/// Writes `pixels` (rgb radiance, row-major, row 0 at the top) to `path`.
pub fn write_image(path: &Path, pixels: &[Vec4], width: u32, height: u32, exposure: f32) -> Result<()> {
    write_layered(path, pixels, &[], width, height, exposure)
}

/// Writes an image and, to an EXR, its named layers: the beauty image as the
/// channels `R`, `G`, `B`, and each layer as `<name>.R`, `<name>.G`,
/// `<name>.B` in the same part (the channel-group convention that Nuke,
/// Blender and OpenImageIO read as layers; readers that know only RGB see
/// the beauty image). A PNG gets the tone-mapped beauty image only.
pub fn write_layered(
    path: &Path,
    pixels: &[Vec4],
    layers: &[(&str, &[Vec4])],
    width: u32,
    height: u32,
    exposure: f32,
) -> Result<()> {
    let bytes = encode(path, pixels, layers, width, height, exposure)?;
    write_atomically(path, &bytes)
}

/// The bytes `write_layered` writes to `path` (its format by its extension).
pub fn encode(
    path: &Path,
    pixels: &[Vec4],
    layers: &[(&str, &[Vec4])],
    width: u32,
    height: u32,
    exposure: f32,
) -> Result<Vec<u8>> {
    if format_of(path)? == Format::Exr {
        return layered_exr(pixels, layers, width, height)
            .with_context(|| format!("{}: cannot encode", path.display()));
    }
    let mut bytes = std::io::Cursor::new(Vec::new());
    tone_map(pixels, width, height, exposure).write_to(&mut bytes, ImageFormat::Png)?;
    Ok(bytes.into_inner())
}

/// Writes the image (with its per-pass `layers`) to every path in `images`,
/// each in the format its extension names (`encode`), and the `extra`
/// files, all or none (`write_all`): what `render` and the viewer's `S`
/// write.
pub fn write_images(
    images: &[std::path::PathBuf],
    pixels: &[Vec4],
    layers: &[(&str, &[Vec4])],
    (width, height, exposure): (u32, u32, f32),
    extra: &[(&Path, &[u8])],
) -> Result<()> {
    let mut encoded = Vec::with_capacity(images.len());
    for p in images {
        encoded.push(encode(p, pixels, layers, width, height, exposure)?);
    }
    let mut files: Vec<(&Path, &[u8])> =
        images.iter().map(|p| p.as_path()).zip(encoded.iter().map(|b| b.as_slice())).collect();
    files.extend_from_slice(extra);
    write_all(&files)
}

/// The name every temporary file of an output starts with: a later run
/// removes stale ones (`remove_stale_temporaries`).
pub const TEMPORARY_PREFIX: &str = ".slicelight-tmp-";

/// A temporary file older than this in an output's folder is left from a
/// process that was killed (SIGKILL) while writing: writing an output takes
/// seconds, not an hour.
const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(3600);

/// The temporary files this process is writing now: the signal handler
/// removes them (`remove_temporaries_on_signal`).
static STAGED: std::sync::Mutex<Vec<std::path::PathBuf>> = std::sync::Mutex::new(Vec::new());

/// On SIGINT, SIGTERM or SIGHUP: removes the temporary files being written
/// (outputs are renamed into place only when all are whole, so none is
/// half-written) and exits with 130.
pub fn remove_temporaries_on_signal() {
    let installed = ctrlc::set_handler(|| {
        let staged = STAGED.lock().map(|s| s.clone()).unwrap_or_default();
        for p in &staged {
            let _ = std::fs::remove_file(p);
        }
        eprintln!("slicelight: interrupted; no output was half-written");
        std::process::exit(130);
    });
    if let Err(e) = installed {
        eprintln!("slicelight: warning: cannot handle SIGINT/SIGTERM ({e}); an interrupted write may leave a {TEMPORARY_PREFIX}* file");
    }
}

/// Removes `TEMPORARY_PREFIX` files in `dir` older than `STALE_AFTER`.
pub fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let name = e.file_name();
        if !name.to_string_lossy().starts_with(TEMPORARY_PREFIX) {
            continue;
        }
        let old = e.metadata().and_then(|m| m.modified()).ok().and_then(|t| t.elapsed().ok());
        if old.is_some_and(|age| age > STALE_AFTER) && e.file_type().is_ok_and(|t| t.is_file()) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// A temporary file for `path` in its folder, registered for the signal
/// handler until `finish` renames it into place.
struct Staged {
    /// Taken by `finish`.
    file: Option<tempfile::NamedTempFile>,
}

impl Staged {
    fn new(path: &Path) -> Result<Staged> {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        remove_stale_temporaries(dir);
        let file = tempfile::Builder::new()
            .prefix(TEMPORARY_PREFIX)
            .tempfile_in(dir)
            .with_context(|| format!("{}: cannot create a file in {}", path.display(), dir.display()))?;
        if let Ok(mut s) = STAGED.lock() {
            s.push(file.path().to_path_buf());
        }
        Ok(Staged { file: Some(file) })
    }

    fn write(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        let file = self.file.as_mut().expect("not finished");
        file.write_all(bytes).with_context(|| format!("{}: write failed", path.display()))?;
        // The temporary file is private (0600); the result is an ordinary file.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            file.as_file().set_permissions(std::fs::Permissions::from_mode(0o644))?;
        }
        Ok(())
    }

    fn finish(mut self, path: &Path) -> Result<()> {
        let file = self.file.take().expect("not finished");
        let tmp = file.path().to_path_buf();
        let done = file.persist(path).map_err(|e| anyhow!("{}: cannot write: {}", path.display(), e.error));
        unstage(&tmp);
        done.map(|_| ())
    }
}

fn unstage(tmp: &Path) {
    if let Ok(mut s) = STAGED.lock() {
        s.retain(|p| p != tmp);
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        // Not renamed (an error before `finish`): the file goes with it.
        if let Some(f) = &self.file {
            unstage(f.path());
        }
    }
}

/// Writes every `(path, bytes)` or none: each goes to a temporary file in
/// its folder first, and only when all are written whole are they renamed
/// over their paths (a full disk or an unwritable folder for the last one
/// leaves every earlier path as it was).
pub fn write_all(files: &[(&Path, &[u8])]) -> Result<()> {
    let mut staged = Vec::with_capacity(files.len());
    for (path, bytes) in files {
        let mut tmp = Staged::new(path)?;
        tmp.write(path, bytes)?;
        staged.push((tmp, *path));
    }
    // A failpoint for the interruption test (tests/cli.rs): hold the
    // written temporaries this long before renaming them.
    if let Some(ms) = std::env::var("SLICELIGHT_FAILPOINT_STALL_BEFORE_RENAME_MS").ok().and_then(|v| v.parse().ok()) {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
    for (tmp, path) in staged {
        tmp.finish(path)?;
    }
    Ok(())
}

fn layered_exr(pixels: &[Vec4], layers: &[(&str, &[Vec4])], width: u32, height: u32) -> Result<Vec<u8>> {
    let channel = |img: &[Vec4], c: usize| img.iter().map(|p| p[c]).collect::<Vec<f32>>();
    let mut channels = Vec::new();
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        channels.push((name.to_string(), channel(pixels, c)));
        for (layer, img) in layers {
            channels.push((format!("{layer}.{name}"), channel(img, c)));
        }
    }
    exr_bytes(width, height, channels)
}

/// An EXR file of `channels` (a name and `width x height` values each, rows
/// from the top): RLE-compressed tiles of 64x64, written in increasing
/// order, so the same pixels give the same bytes on every run. (The
/// encoder's default order is "unspecified": its parallel compression then
/// wrote the tiles in the order they finished, and the same terrain came
/// out as different files on four runs in six.)
pub fn exr_bytes(width: u32, height: u32, channels: Vec<(String, Vec<f32>)>) -> Result<Vec<u8>> {
    use exr::prelude::*;
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> =
        channels.into_iter().map(|(name, values)| AnyChannel::new(name.as_str(), FlatSamples::F32(values))).collect();
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::named("slicelight"),
        Encoding { line_order: LineOrder::Increasing, ..Encoding::FAST_LOSSLESS },
        AnyChannels::sort(channels),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut bytes).map_err(|e| anyhow!("{e}"))?;
    Ok(bytes.into_inner())
}

/// Writes `bytes` to `path` through a temporary file in the same folder, so
/// that `path` either keeps its old contents or gets all of the new ones.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp = Staged::new(path)?;
    tmp.write(path, bytes)?;
    tmp.finish(path)
}

/// Where results worth keeping between runs go (the caustics' light
/// transport tables, the smoke's simulation states): `SLICELIGHT_CACHE_DIR`
/// (`off`: no cache), else `$XDG_CACHE_HOME/slicelight/tables`, else
/// `~/.cache/slicelight/tables`.
pub fn cache_directory() -> Option<std::path::PathBuf> {
    use std::path::PathBuf;
    match std::env::var_os("SLICELIGHT_CACHE_DIR") {
        Some(d) if d == "off" => None,
        // An empty value is unset (not the working folder).
        Some(d) if !d.is_empty() => Some(PathBuf::from(d)),
        _ => {
            let base = std::env::var_os("XDG_CACHE_HOME")
                .map(PathBuf::from)
                .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
            Some(base.join("slicelight").join("tables"))
        }
    }
}

/// FNV-1a over `bytes`: a hash stable across runs and builds, for the
/// names of cached results.
pub fn stable_hash(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// The stable hash of a cached result's `key`, its family's format
/// `version` and the digest of the kernels' sources: a result written by
/// other kernels is never read back.
pub fn cache_key(version: u32, key: &str) -> u64 {
    let digest = include_str!("../spirv/slicelight_shaders.digest");
    stable_hash(format!("{version}|{digest}|{key}").as_bytes())
}

/// Whether the command line asked for no messages but errors (`--quiet`):
/// notes from deep inside a render (a cached state used) respect it.
pub static QUIET: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Prints a note on stderr unless `QUIET`.
pub fn note(text: &str) {
    if !QUIET.load(std::sync::atomic::Ordering::Relaxed) {
        eprintln!("{text}");
    }
}

/// Most bytes of a scene file.
pub const MAX_SCENE_BYTES: u64 = 64 << 20;
/// Most bytes of an input image (light maps, heights, sea bottoms, `compare`).
pub const MAX_IMAGE_BYTES: u64 = 1 << 30;
/// Most bytes of a mesh, a metaball list or a density grid.
pub const MAX_DATA_BYTES: u64 = 4 << 30;

/// Checks, before reading it, that `path` is a regular file (not a folder,
/// a device such as /dev/zero, a FIFO or a socket, which could be read
/// without end or block forever) of at most `limit` bytes; the error names
/// `field` and the path. A path that cannot be looked at (missing) passes:
/// the read that follows reports it in its own words.
pub fn regular_file(field: &str, path: &std::path::Path, limit: u64) -> anyhow::Result<u64> {
    let Ok(meta) = std::fs::metadata(path) else { return Ok(0) };
    if !meta.is_file() {
        anyhow::bail!(
            "{field}: {}: expected a regular file, got a {}",
            path.display(),
            if meta.is_dir() { "folder" } else { "device, FIFO or socket" }
        );
    }
    if meta.len() > limit {
        anyhow::bail!("{field}: {}: expected at most {limit} bytes, got {}", path.display(), meta.len());
    }
    Ok(meta.len())
}

/// Prints a line on stdout; a closed pipe (`| head -1`) ends the program
/// quietly with success, as the reader has what it wanted.
pub fn say(line: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = writeln!(out, "{line}").and_then(|_| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("slicelight: error: stdout: {e}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod write_tests {
    use super::*;

    #[test]
    fn a_failing_output_leaves_every_other_output_as_it_was() {
        // The second file cannot be created (/proc takes no new files, even
        // from root): the first keeps its old bytes, no temporary is left.
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("ok.png");
        std::fs::write(&ok, b"old").unwrap();
        let bad = Path::new("/proc/slicelight-test.png");
        let err = write_all(&[(ok.as_path(), b"new"), (bad, b"new")]).unwrap_err();
        assert!(err.to_string().contains("/proc/slicelight-test.png"), "{err}");
        assert_eq!(std::fs::read(&ok).unwrap(), b"old");
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left.len(), 1, "{left:?}");
        // And when all can be written, all are.
        let other = dir.path().join("b.exr");
        write_all(&[(ok.as_path(), b"new"), (other.as_path(), b"two")]).unwrap();
        assert_eq!((std::fs::read(&ok).unwrap(), std::fs::read(&other).unwrap()), (b"new".to_vec(), b"two".to_vec()));
    }

    #[test]
    fn the_same_pixels_give_the_same_exr_bytes() {
        // 64 tiles of varied content (RLE's work differs from tile to tile,
        // so a parallel encoder finishes them out of order), written 8
        // times; and read back as written.
        let (w, h) = (512u32, 512u32);
        let values: Vec<f32> = (0..w * h).map(|i| ((i * 2_654_435_761) >> 20) as f32 * (i % 7) as f32).collect();
        let channels = || ["R", "G", "B"].map(|c| (c.to_string(), values.clone())).to_vec();
        let first = exr_bytes(w, h, channels()).unwrap();
        for run in 1..8 {
            assert!(exr_bytes(w, h, channels()).unwrap() == first, "run {run} wrote other bytes");
        }
        let back = image::load_from_memory(&first).unwrap().to_rgb32f();
        assert!(back.pixels().zip(&values).all(|(p, &v)| p.0 == [v; 3]));
    }
}
