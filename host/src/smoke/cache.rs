//! Simulation states on disk: after a render steps the fluid, its state is
//! written to the cache folder (`output::cache_directory`), so that a later
//! process (the next frames of an animation, another machine's range of
//! frames over a shared folder, a render resumed after a stop) starts from
//! the latest state at or before its time instead of from rest. The steps
//! are deterministic, so a restarted state continues bit for bit as the
//! uninterrupted run would. The newest `KEEP` states per configuration are
//! kept; older ones are removed.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

use super::{Config, Fluid, Puff};

const MAGIC: &[u8; 8] = b"SLSMOKE1";
/// States kept per configuration.
pub const KEEP: usize = 4;

/// Bump when a step's result changes for the same configuration (the
/// kernels' changes are caught by their sources' digest, below).
const VERSION: u32 = 2;

/// A stable 64-bit hash of a configuration's key, the state's version and
/// the digest of the kernels' sources (`output::cache_key`): a state
/// written by other code is never read back.
pub fn key_hash(key: &str) -> u64 {
    crate::output::cache_key(VERSION, key)
}

fn file_name(hash: u64, step: u32) -> String {
    format!("smoke-{hash:016x}-{step:09}.state")
}

/// The cached states of `hash` in `dir`, by step.
fn states(dir: &Path, hash: u64) -> Vec<(u32, PathBuf)> {
    let prefix = format!("smoke-{hash:016x}-");
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut out: Vec<(u32, PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let step = name.strip_prefix(&prefix)?.strip_suffix(".state")?.parse().ok()?;
            Some((step, e.path()))
        })
        .collect();
    out.sort();
    out
}

fn put_f32s(out: &mut Vec<u8>, v: &[f32]) {
    out.extend_from_slice(&(v.len() as u64).to_le_bytes());
    out.extend_from_slice(bytemuck::cast_slice(v));
}

/// Writes `fluid`'s state (its arrays, puffs and emission counters) as
/// `hash`'s state at its step, whole or not at all, and removes all but
/// the newest `KEEP` states of `hash`.
pub fn save(dir: &Path, hash: u64, fluid: &Fluid) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the cache folder", dir.display()))?;
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&hash.to_le_bytes());
    out.extend_from_slice(&fluid.params.step.to_le_bytes());
    out.extend_from_slice(&fluid.emitted.to_le_bytes());
    for q in [&fluid.u, &fluid.v, &fluid.w, &fluid.temperature, &fluid.smoke, &fluid.phi, &fluid.owed] {
        put_f32s(&mut out, q);
    }
    let puffs: Vec<f32> = fluid
        .puffs
        .iter()
        .flat_map(|p| [p.position.x, p.position.y, p.position.z, p.age, p.radius, p.density])
        .collect();
    put_f32s(&mut out, &puffs);
    let path = dir.join(file_name(hash, fluid.params.step));
    crate::output::write_atomically(&path, &out)?;
    let all = states(dir, hash);
    for (_, old) in all.iter().take(all.len().saturating_sub(KEEP)) {
        let _ = std::fs::remove_file(old);
    }
    Ok(path)
}

/// Reads a state written by `save` into a fluid started from `config` on
/// `cells` (what the file does not hold: the grid, the sources, the rules).
fn read(path: &Path, hash: u64, config: &Config, cells: &[u32]) -> Result<Fluid> {
    crate::output::regular_file("smoke state", path, crate::output::MAX_DATA_BYTES)?;
    let bytes = std::fs::read(path)?;
    decode(&bytes, hash, config, cells)
}

/// A state file's bytes as a fluid started from `config` on `cells`; an
/// error for anything but a whole state of this configuration.
pub fn decode(bytes: &[u8], hash: u64, config: &Config, cells: &[u32]) -> Result<Fluid> {
    let mut at = 0usize;
    let mut take = |n: usize| -> Result<&[u8]> {
        // A length read from the file may be anything: `at + n` is checked
        // (found by fuzzing: a length near 2^64 overflowed it).
        let s = at.checked_add(n).and_then(|end| bytes.get(at..end)).context("truncated")?;
        at += n;
        Ok(s)
    };
    if take(8)? != MAGIC {
        bail!("not a smoke state");
    }
    let word = |b: &[u8]| u64::from_le_bytes(b.try_into().expect("8 bytes"));
    if word(take(8)?) != hash {
        bail!("another configuration's state");
    }
    let step = u32::from_le_bytes(take(4)?.try_into()?);
    let emitted = u32::from_le_bytes(take(4)?.try_into()?);
    let mut arrays = Vec::new();
    for _ in 0..8 {
        let n = word(take(8)?) as usize;
        let raw = take(n.checked_mul(4).context("size")?)?;
        arrays.push(raw.as_chunks::<4>().0.iter().map(|c| f32::from_le_bytes(*c)).collect::<Vec<_>>());
    }
    let mut f = config.start(cells.to_vec());
    let [u, v, w, t, s, phi, owed, puffs]: [Vec<f32>; 8] = arrays.try_into().expect("eight arrays");
    let fits = [(&u, f.u.len()), (&v, f.v.len()), (&w, f.w.len()), (&t, f.temperature.len()), (&s, f.smoke.len())];
    if fits.iter().any(|(a, n)| a.len() != *n) || phi.len() != f.phi.len() || owed.len() != f.owed.len() {
        bail!("array sizes differ from the configuration's");
    }
    (f.u, f.v, f.w, f.temperature, f.smoke, f.phi, f.owed) = (u, v, w, t, s, phi, owed);
    f.puffs = puffs
        .as_chunks::<6>()
        .0
        .iter()
        .map(|p| Puff { position: glam::Vec3::new(p[0], p[1], p[2]), age: p[3], radius: p[4], density: p[5] })
        .collect();
    f.emitted = emitted;
    f.params.step = step;
    Ok(f)
}

/// The latest cached state of `hash` at or before `step`, if one reads
/// back whole; a damaged file is skipped.
pub fn load(dir: &Path, hash: u64, step: u64, config: &Config, cells: &[u32]) -> Option<Fluid> {
    states(dir, hash)
        .into_iter()
        .rev()
        .filter(|(s, _)| *s as u64 <= step)
        .find_map(|(_, p)| read(&p, hash, config, cells).ok())
}
