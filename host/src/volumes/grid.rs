//! Density grids from files: Mitsuba's `.vol` format (version 3, float32,
//! one channel), read whole and checked, and written (for tests and tools);
//! and OpenVDB float grids (`read_vdb`, through the `vdb-rs` crate).
//!
//! The layout (Mitsuba 3's `GridVolume` reads the same bytes): the bytes
//! `V O L`, the version byte 3, then little-endian `i32` encoding (1:
//! float32), `i32` cells along x, y and z, `i32` channels (1 here), six
//! `f32` of a bounding box (ignored here, as Mitsuba 3 ignores it: the
//! `[[volume]]`'s `min` and `max` place the grid), and the values, x
//! fastest, then y, then z.

use anyhow::{Context, Result};
use std::path::Path;

/// Bytes before the values.
const HEADER: usize = 48;

/// A grid: cells along x, y, z and the values (x fastest).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    pub cells: [u32; 3],
    pub values: Vec<f32>,
}

/// Reads and checks a `.vol` file; `field` names the scene field in errors.
pub fn read_vol(field: &str, path: &Path) -> Result<Grid> {
    crate::output::regular_file(field, path, crate::output::MAX_DATA_BYTES)?;
    let bytes = std::fs::read(path).with_context(|| format!("{field}: cannot read {}", path.display()))?;
    parse_vol(field, path, &bytes)
}

/// A `.vol` file's bytes as a grid (`path` names it in errors).
pub fn parse_vol(field: &str, path: &Path, bytes: &[u8]) -> Result<Grid> {
    let fail = |what: String| anyhow::anyhow!("{field}: {}: {what}", path.display());
    if bytes.len() < HEADER || &bytes[0..3] != b"VOL" {
        return Err(fail("not a Mitsuba .vol file (expected the bytes VOL and a 48-byte header)".into()));
    }
    if bytes[3] != 3 {
        return Err(fail(format!("version {}, expected 3", bytes[3])));
    }
    let int = |at: usize| i32::from_le_bytes(bytes[at..at + 4].try_into().expect("four bytes"));
    let encoding = int(4);
    if encoding != 1 {
        return Err(fail(format!("encoding {encoding}, expected 1 (float32)")));
    }
    let (nx, ny, nz, channels) = (int(8), int(12), int(16), int(20));
    if channels != 1 {
        return Err(fail(format!("{channels} channels, expected 1 (a density)")));
    }
    if ![nx, ny, nz].iter().all(|n| (1..=4096).contains(n)) {
        return Err(fail(format!("cells {nx} x {ny} x {nz}, expected 1..=4096 each")));
    }
    let count = nx as usize * ny as usize * nz as usize;
    let expected = HEADER + 4 * count;
    if bytes.len() != expected {
        return Err(fail(format!("{} bytes, expected {expected} for {nx} x {ny} x {nz} float32 values", bytes.len())));
    }
    let values: Vec<f32> = bytes[HEADER..].as_chunks::<4>().0.iter().map(|c| f32::from_le_bytes(*c)).collect();
    if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
        let (x, y, z) = (i % nx as usize, (i / nx as usize) % ny as usize, i / (nx as usize * ny as usize));
        return Err(fail(format!("the density at cell ({x}, {y}, {z}) is {v}, expected a finite value >= 0")));
    }
    Ok(Grid { cells: [nx as u32, ny as u32, nz as u32], values })
}

/// Whether `file` names an OpenVDB file (by its extension, `.vdb`).
pub fn is_vdb(file: &str) -> bool {
    Path::new(file).extension().is_some_and(|e| e.eq_ignore_ascii_case("vdb"))
}

/// Reads an OpenVDB file's float grid `name` (default: the grid named
/// `density`, else the file's only grid) as a dense grid over the bounding
/// box of its active voxels and tiles: cell `i` holds voxel `min + i`, so
/// the `[[volume]]`'s box spans the voxels' unit cubes `[min - 0.5, max +
/// 0.5]` as it spans a `.vol` file's cells (the file's own transform is
/// not used: the box places the grid). Inactive voxels are 0 (a fog
/// volume's background); grids saved as half floats are refused. A grid of
/// more than `max_cells` voxels is box-filtered by the smallest whole
/// factor `k` per axis that fits: each cell the mean of a `k^3` block.
/// Every active value must be finite and non-negative; `field` names the
/// scene field in errors.
pub fn read_vdb(field: &str, path: &Path, name: Option<&str>, max_cells: u64) -> Result<Grid> {
    crate::output::regular_file(&format!("{field}.file"), path, crate::output::MAX_DATA_BYTES)?;
    let fail = |what: String| anyhow::anyhow!("{field}.file: {}: {what}", path.display());
    let file = std::fs::File::open(path).map_err(|e| fail(format!("cannot open it: {e}")))?;
    // vdb-rs may panic on a malformed file; that is the file's error here.
    let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> Result<vdb_rs::Grid<f32>> {
        let mut reader = vdb_rs::VdbReader::new(std::io::BufReader::new(file))
            .map_err(|e| fail(format!("not an OpenVDB file vdb-rs can read ({e})")))?;
        let mut names = reader.available_grids();
        names.sort();
        let chosen = match name {
            Some(n) if names.iter().any(|m| m == n) => n.to_string(),
            Some(n) => {
                return Err(anyhow::anyhow!(
                    "{field}.name: {}: no grid named {n:?}; the file holds {names:?}",
                    path.display()
                ))
            }
            None if names.iter().any(|m| m == "density") => "density".to_string(),
            None if names.len() == 1 => names[0].clone(),
            None => return Err(fail(format!("holds the grids {names:?}: name one with `name`"))),
        };
        let descriptor = &reader.grid_descriptors[&chosen];
        let kind = &descriptor.grid_type;
        if !kind.starts_with("Tree_float_") {
            return Err(fail(format!("grid {chosen:?} is a {kind}, expected a float grid (Tree_float_*)")));
        }
        if descriptor.meta_data.is_half_float() {
            // vdb-rs 0.6 reads a half-float grid's node headers as f32 and
            // then asks for exabytes (an abort, not an error): refused here.
            return Err(fail(format!(
                "grid {chosen:?} is saved as half floats, which the vdb-rs reader cannot read; \
                 save it as 32-bit floats (OpenVDB: saveFloatAsHalf = false)"
            )));
        }
        reader.read_grid::<f32>(&chosen).map_err(|e| fail(format!("grid {chosen:?}: {e}")))
    }));
    let grid = match read {
        Ok(r) => r?,
        Err(_) => return Err(fail("vdb-rs could not parse it (it panicked)".into())),
    };
    // The active voxels' and tiles' bounds, index space, inclusive.
    let (mut lo, mut hi) = (glam::IVec3::splat(i32::MAX), glam::IVec3::splat(i32::MIN));
    for (at, value, level) in grid.iter() {
        let at = glam::IVec3::new(at.x as i32, at.y as i32, at.z as i32);
        if !(value.is_finite() && value >= 0.0) {
            return Err(fail(format!(
                "the density at voxel ({}, {}, {}) is {value}, expected a finite value >= 0",
                at.x, at.y, at.z
            )));
        }
        lo = lo.min(at);
        hi = hi.max(at + glam::IVec3::splat(level.scale() as i32 - 1));
    }
    if lo.x > hi.x {
        // No active voxel: an empty cloud.
        return Ok(Grid { cells: [1, 1, 1], values: vec![0.0] });
    }
    let extent = (hi - lo + glam::IVec3::ONE).as_i64vec3();
    let cells_at = |k: i64| (extent + glam::I64Vec3::splat(k - 1)) / k;
    let mut k = 1i64;
    while cells_at(k).element_product() as u64 > max_cells || cells_at(k).max_element() > 4096 {
        k += 1;
    }
    let n = cells_at(k);
    let mut values = vec![0.0f32; n.element_product() as usize];
    let weight = 1.0 / (k * k * k) as f32;
    for (at, value, level) in grid.iter() {
        let at = glam::I64Vec3::new(at.x as i64, at.y as i64, at.z as i64) - lo.as_i64vec3();
        let size = level.scale() as i64;
        for z in at.z..at.z + size {
            for y in at.y..at.y + size {
                for x in at.x..at.x + size {
                    let c = glam::I64Vec3::new(x, y, z) / k;
                    values[((c.z * n.y + c.y) * n.x + c.x) as usize] += value * weight;
                }
            }
        }
    }
    Ok(Grid { cells: [n.x as u32, n.y as u32, n.z as u32], values })
}

/// The bytes of a `.vol` file holding `grid` (bounding box `[0, 1]^3`).
pub fn vol_bytes(grid: &Grid) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER + 4 * grid.values.len());
    out.extend_from_slice(b"VOL");
    out.push(3);
    out.extend_from_slice(&1i32.to_le_bytes());
    for n in grid.cells {
        out.extend_from_slice(&(n as i32).to_le_bytes());
    }
    out.extend_from_slice(&1i32.to_le_bytes());
    for b in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0] {
        out.extend_from_slice(&b.to_le_bytes());
    }
    for v in &grid.values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The density of `values` (cells `n`, over the box `[lo, hi]`) at `x`,
/// in f64, as Mitsuba 3 interpolates a grid: 0 outside the box; inside,
/// trilinear between cell centres `lo + (i + 0.5) / n * size`, each
/// coordinate clamped to the outer centres (the edge value held out to
/// the faces).
pub fn density_f64(values: &[f32], n: [u32; 3], lo: glam::DVec3, hi: glam::DVec3, x: glam::DVec3) -> f64 {
    use glam::DVec3;
    if x.cmplt(lo).any() || x.cmpgt(hi).any() {
        return 0.0;
    }
    let nf = DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64);
    let g = ((x - lo) / (hi - lo) * nf - 0.5).clamp(DVec3::ZERO, nf - 1.0);
    let i0 = g.floor();
    let f = g - i0;
    let at = |i: f64, j: f64, k: f64| -> f64 {
        let (i, j, k) = (i.min(nf.x - 1.0) as usize, j.min(nf.y - 1.0) as usize, k.min(nf.z - 1.0) as usize);
        values[(k * n[1] as usize + j) * n[0] as usize + i] as f64
    };
    let mut sum = 0.0;
    for (dk, wk) in [(0.0, 1.0 - f.z), (1.0, f.z)] {
        for (dj, wj) in [(0.0, 1.0 - f.y), (1.0, f.y)] {
            for (di, wi) in [(0.0, 1.0 - f.x), (1.0, f.x)] {
                let w = wi * wj * wk;
                if w > 0.0 {
                    sum += w * at(i0.x + di, i0.y + dj, i0.z + dk);
                }
            }
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn interpolation_follows_mitsuba() {
        // 2 x 1 x 1 cells over [0, 2] x [0, 1] x [0, 1]: centres at x = 0.5
        // and 1.5 hold the values, the edge values hold out to the faces,
        // linear between, 0 outside.
        let values = [1.0f32, 3.0];
        let (lo, hi) = (DVec3::ZERO, DVec3::new(2.0, 1.0, 1.0));
        let d = |x: f64| density_f64(&values, [2, 1, 1], lo, hi, DVec3::new(x, 0.5, 0.5));
        assert_eq!(d(0.5), 1.0);
        assert_eq!(d(1.5), 3.0);
        assert_eq!(d(1.0), 2.0);
        assert_eq!(d(0.0), 1.0);
        assert_eq!(d(0.2), 1.0);
        assert_eq!(d(2.0), 3.0);
        assert_eq!(d(2.0001), 0.0);
        assert_eq!(d(-0.0001), 0.0);
    }

    #[test]
    fn vol_files_round_trip_and_bad_ones_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.vol");
        let grid = Grid { cells: [3, 2, 1], values: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.5] };
        std::fs::write(&path, vol_bytes(&grid)).unwrap();
        assert_eq!(read_vol("volume[0].grid.file", &path).unwrap(), grid);
        let mut bad = vol_bytes(&grid);
        bad.truncate(bad.len() - 4);
        std::fs::write(&path, &bad).unwrap();
        let e = format!("{:#}", read_vol("volume[0].grid.file", &path).unwrap_err());
        assert!(e.contains("volume[0].grid.file") && e.contains("g.vol") && e.contains("bytes"), "{e}");
        let mut nan = vol_bytes(&grid);
        let last = nan.len() - 4;
        nan[last..].copy_from_slice(&f32::NAN.to_le_bytes());
        std::fs::write(&path, &nan).unwrap();
        let e = format!("{:#}", read_vol("f", &path).unwrap_err());
        assert!(e.contains("cell (2, 1, 0)"), "{e}");
        let mut two = vol_bytes(&grid);
        two[20..24].copy_from_slice(&2i32.to_le_bytes());
        std::fs::write(&path, &two).unwrap();
        assert!(format!("{:#}", read_vol("f", &path).unwrap_err()).contains("channels"));
        std::fs::write(&path, b"not a grid at all, just text that is long enough to hold a header").unwrap();
        assert!(format!("{:#}", read_vol("f", &path).unwrap_err()).contains("not a Mitsuba .vol"));
    }
}
