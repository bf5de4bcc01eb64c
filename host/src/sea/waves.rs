//! Wind waves for the sea's surface: a statistical spectrum on an FFT grid
//! (Tessendorf, "Simulating Ocean Water", the paper's ref. 22) at one
//! instant `t`, turned into a tiling map of surface normals. Each mode's
//! phase advances by the deep-water dispersion relation, `h(k, t) = h(k)
//! exp(-i w(k) t)` with `w^2 = g k`: the waves travel downwind, each at
//! its own phase speed `w / k`.
//!
//! The spectrum is JONSWAP (Hasselmann et al. 1973), which knows the fetch:
//! `S(w) = alpha g^2 w^-5 exp(-5/4 (w_p/w)^4) gamma^r` (m^2 s), with
//! `alpha = 0.076 (U^2/(F g))^0.22`, `w_p = 22 (g^2/(U F))^(1/3)`, `gamma = 3.3`,
//! spread over directions by `(2/pi) cos^2` around the wind, and carried to
//! wavenumbers by deep-water dispersion `w^2 = g k`:
//! `Psi(k) = S(w) D(theta) (dw/dk) / k` (m^4), the variance of the height
//! per unit of wavenumber area. Each grid mode gets a complex Gaussian
//! amplitude of variance `2 Psi dk^2`; the slopes are the real parts of the
//! inverse transforms of `i k_x h` and `i k_z h`.

use anyhow::{bail, Result};
use glam::{Vec3, Vec4};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::Deserialize;

use crate::scene::invalid;

const GRAVITY: f64 = 9.81;

/// `waves = { kind = "spectrum", ... }` of `[sea]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spectrum {
    /// Wind speed 10 m above the sea, m/s.
    pub wind_m_s: f32,
    /// Distance the wind has blown over open water, m.
    #[serde(default = "open_ocean")]
    pub fetch_m: f32,
    /// Side of the square tile the grid covers, m (the map repeats).
    pub size_m: f32,
    /// Grid points per side (a power of two).
    #[serde(default = "grid")]
    pub resolution: u32,
    /// Direction the wind blows toward, degrees from +x toward +z.
    #[serde(default)]
    pub wind_direction_deg: f32,
    /// Seed of the random amplitudes.
    #[serde(default)]
    pub seed: u64,
    /// Whether each sample reads the slopes under its footprint (true) or
    /// at its point (false: sparkles where a pixel covers many waves).
    #[serde(default = "filtered")]
    pub filter: bool,
    /// The waves shorter than the grid's texels, as slope variance added
    /// to every footprint: `"cox-munk"` (Cox and Munk's clean-surface
    /// measurements minus what the grid resolves) or `"none"`.
    #[serde(default)]
    pub roughness: Roughness,
}

/// `roughness` of a wave spectrum.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Roughness {
    #[default]
    CoxMunk,
    None,
}

fn filtered() -> bool {
    true
}

fn open_ocean() -> f32 {
    100_000.0
}
fn grid() -> u32 {
    256
}

impl Spectrum {
    fn validate(&self) -> Result<()> {
        if !(self.wind_m_s.is_finite() && self.wind_m_s > 0.0 && self.wind_m_s <= 100.0) {
            bail!(invalid("sea.waves.wind_m_s", "a wind speed in (0, 100] m/s", self.wind_m_s));
        }
        if !(self.fetch_m.is_finite() && self.fetch_m >= 100.0 && self.fetch_m <= 1e7) {
            bail!(invalid("sea.waves.fetch_m", "a fetch in [100, 1e7] m", self.fetch_m));
        }
        if !(self.size_m.is_finite() && self.size_m > 0.0 && self.size_m <= 1e5) {
            bail!(invalid("sea.waves.size_m", "a tile size in (0, 1e5] m", self.size_m));
        }
        if !(self.resolution.is_power_of_two() && (4..=4096).contains(&self.resolution)) {
            bail!(invalid("sea.waves.resolution", "a power of two in 4..=4096", self.resolution));
        }
        if !self.wind_direction_deg.is_finite() {
            bail!(invalid("sea.waves.wind_direction_deg", "a finite angle in degrees", self.wind_direction_deg));
        }
        Ok(())
    }

    /// JONSWAP's variance density over angular frequency, m^2 s.
    pub fn jonswap(&self, w: f64) -> f64 {
        let (u, f) = (self.wind_m_s as f64, self.fetch_m as f64);
        let alpha = 0.076 * (u * u / (f * GRAVITY)).powf(0.22);
        let wp = 22.0 * (GRAVITY * GRAVITY / (u * f)).powf(1.0 / 3.0);
        let sigma = if w <= wp { 0.07 } else { 0.09 };
        let r = (-(w - wp).powi(2) / (2.0 * sigma * sigma * wp * wp)).exp();
        alpha * GRAVITY * GRAVITY * w.powi(-5) * (-1.25 * (wp / w).powi(4)).exp() * 3.3f64.powf(r)
    }

    /// The height variance per unit wavenumber area at `(kx, kz)`, m^4.
    pub fn psi(&self, kx: f64, kz: f64) -> f64 {
        let k = (kx * kx + kz * kz).sqrt();
        if k <= 0.0 {
            return 0.0;
        }
        let w = (GRAVITY * k).sqrt();
        let wind = (self.wind_direction_deg as f64).to_radians();
        let cos = (kx * wind.cos() + kz * wind.sin()) / k;
        if cos <= 0.0 {
            return 0.0;
        }
        let spread = 2.0 / std::f64::consts::PI * cos * cos;
        self.jonswap(w) * spread * (GRAVITY / (2.0 * w)) / k
    }

    /// The tile's unit surface normals (y up) at time `t` (s), row `z` by
    /// column `x`, `resolution^2`.
    pub fn normal_map(&self, t: f64) -> Result<Vec<Vec4>> {
        self.validate()?;
        let n = self.resolution as usize;
        let dk = 2.0 * std::f64::consts::PI / self.size_m as f64;
        let mut rng = rand::rngs::StdRng::seed_from_u64(self.seed);
        let mut sx = vec![Complex::new(0.0f64, 0.0); n * n];
        let mut sz = sx.clone();
        let signed = |i: usize| if i < n / 2 { i as f64 } else { i as f64 - n as f64 };
        for j in 0..n {
            for i in 0..n {
                let (kx, kz) = (signed(i) * dk, signed(j) * dk);
                let xr: f64 = StandardNormal.sample(&mut rng);
                let xi: f64 = StandardNormal.sample(&mut rng);
                let k = (kx * kx + kz * kz).sqrt();
                let phase = Complex::from_polar(1.0, -(GRAVITY * k).sqrt() * t);
                let h = Complex::new(xr, xi) * (self.psi(kx, kz) * dk * dk).sqrt() * phase;
                sx[j * n + i] = Complex::new(0.0, kx) * h;
                sz[j * n + i] = Complex::new(0.0, kz) * h;
            }
        }
        let fft = FftPlanner::new().plan_fft_inverse(n);
        for field in [&mut sx, &mut sz] {
            inverse_2d(field, n, &*fft);
        }
        Ok(sx
            .iter()
            .zip(&sz)
            .map(|(dx, dz)| Vec3::new(-dx.re as f32, 1.0, -dz.re as f32).normalize().extend(0.0))
            .collect())
    }
}

/// The slope-moment pyramid of a `n x n` normal map (`surface`'s layout):
/// level 0 the slopes `s = (-n_x/n_y, -n_z/n_y)` and their products at each
/// texel, each further level the 2 x 2 means of the one below, down to one
/// texel (`4 n^2 / 3` texels of two `Vec4`s).
pub fn slope_pyramid(normals: &[Vec4], n: usize) -> Vec<Vec4> {
    let mut level: Vec<[f32; 5]> = normals
        .iter()
        .map(|m| {
            let (sx, sz) = (-m.x / m.y, -m.z / m.y);
            [sx, sz, sx * sx, sz * sz, sx * sz]
        })
        .collect();
    let mut out = Vec::with_capacity(normals.len() * 8 / 3 + 2);
    let mut size = n;
    loop {
        for t in &level {
            out.push(Vec4::new(t[0], t[1], t[2], t[3]));
            out.push(Vec4::new(t[4], 0.0, 0.0, 0.0));
        }
        if size == 1 {
            return out;
        }
        let half = size / 2;
        let mut next = vec![[0.0f32; 5]; half * half];
        for (j, row) in next.chunks_mut(half).enumerate() {
            for (i, texel) in row.iter_mut().enumerate() {
                for k in 0..5 {
                    let at = |x: usize, z: usize| level[(2 * j + z) * size + 2 * i + x][k];
                    texel[k] = 0.25 * (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1));
                }
            }
        }
        level = next;
        size = half;
    }
}

impl Spectrum {
    /// The slope covariance `(xx, zz, xz, 0)` of the waves the grid does not
    /// resolve: Cox and Munk's (1954) clean-surface variances along and
    /// across the wind, `3.16e-3 U` and `0.003 + 1.92e-3 U`, less the map's
    /// own along each (never below 0), turned from the wind's axes to x, z.
    pub fn unresolved_roughness(&self, normals: &[Vec4]) -> Vec4 {
        if self.roughness == Roughness::None {
            return Vec4::ZERO;
        }
        let u = self.wind_m_s as f64;
        let a = (self.wind_direction_deg as f64).to_radians();
        let (c, s) = (a.cos(), a.sin());
        let (mut along, mut across) = (0.0f64, 0.0f64);
        for m in normals {
            let (sx, sz) = ((-m.x / m.y) as f64, (-m.z / m.y) as f64);
            along += (sx * c + sz * s).powi(2);
            across += (-sx * s + sz * c).powi(2);
        }
        let count = normals.len().max(1) as f64;
        let up = (3.16e-3 * u - along / count).max(0.0);
        let cross = (0.003 + 1.92e-3 * u - across / count).max(0.0);
        Vec4::new(
            (up * c * c + cross * s * s) as f32,
            (up * s * s + cross * c * c) as f32,
            ((up - cross) * c * s) as f32,
            0.0,
        )
    }
}

/// The unnormalised inverse 2D transform of a row-major `n x n` grid in place.
fn inverse_2d(field: &mut [Complex<f64>], n: usize, fft: &dyn rustfft::Fft<f64>) {
    fft.process(field);
    let mut column = vec![Complex::new(0.0, 0.0); n];
    for i in 0..n {
        for j in 0..n {
            column[j] = field[j * n + i];
        }
        fft.process(&mut column);
        for j in 0..n {
            field[j * n + i] = column[j];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sea(wind: f32) -> Spectrum {
        Spectrum {
            wind_m_s: wind,
            fetch_m: 100_000.0,
            size_m: 200.0,
            resolution: 128,
            wind_direction_deg: 0.0,
            seed: 7,
            filter: true,
            roughness: Roughness::CoxMunk,
        }
    }

    #[test]
    fn mean_square_slope_is_the_spectrums_and_grows_with_the_wind() {
        // Each mode's slope has variance k_x^2 Psi dk^2 (its amplitude's
        // 2 Psi dk^2, halved by taking the real part), so the tile's mean
        // square slope is expected at sum (k_x^2 + k_z^2) Psi dk^2; 16384
        // random samples of a sum dominated by ~1000 modes: within 10 %. Cox
        // and Munk (1954) measured 0.003 + 5.12e-3 U on real seas, capillary
        // waves included, which a 1.6 m grid does not resolve: an upper bound.
        let mut previous = 0.0;
        for wind in [3.0f32, 7.0, 12.0] {
            let s = sea(wind);
            let normals = s.normal_map(0.0).unwrap();
            let mss = normals.iter().map(|n| (n.x * n.x + n.z * n.z) / (n.y * n.y)).sum::<f32>() as f64
                / normals.len() as f64;
            let n = s.resolution as i64;
            let dk = 2.0 * std::f64::consts::PI / s.size_m as f64;
            let mut expected = 0.0;
            for j in -n / 2..n / 2 {
                for i in -n / 2..n / 2 {
                    let (kx, kz) = (i as f64 * dk, j as f64 * dk);
                    expected += (kx * kx + kz * kz) * s.psi(kx, kz) * dk * dk;
                }
            }
            let cox_munk = 0.003 + 5.12e-3 * wind as f64;
            assert!((mss / expected - 1.0).abs() < 0.1, "wind {wind}: mss {mss} vs the spectrum's {expected}");
            assert!(expected > previous && expected < cox_munk, "wind {wind}: {expected} vs Cox-Munk {cox_munk}");
            previous = expected;
        }
    }

    #[test]
    fn waves_move_with_time_and_keep_their_statistics() {
        // Only downwind modes carry energy (no mode meets its opposite), so
        // the tile's mean square slope is the same at every instant (the
        // sum of each mode's |amplitude|^2 / 2) while the map itself moves.
        let s = sea(7.0);
        let mss = |m: &[Vec4]| m.iter().map(|n| ((n.x * n.x + n.z * n.z) / (n.y * n.y)) as f64).sum::<f64>();
        let (a, b) = (s.normal_map(0.0).unwrap(), s.normal_map(2.5).unwrap());
        assert_ne!(a, b);
        assert!((mss(&a) / mss(&b) - 1.0).abs() < 1e-4, "{} {}", mss(&a), mss(&b));
    }

    #[test]
    fn the_map_is_reproducible_and_unit() {
        let (a, b) = (sea(7.0).normal_map(0.0).unwrap(), sea(7.0).normal_map(0.0).unwrap());
        assert_eq!(a, b);
        assert!(a.iter().all(|n| (n.truncate().length() - 1.0).abs() < 1e-5 && n.y > 0.0));
    }

    #[test]
    fn bad_settings_name_the_field() {
        let mut s = sea(7.0);
        s.resolution = 100;
        let e = s.normal_map(0.0).unwrap_err().to_string();
        assert!(e.contains("sea.waves.resolution"), "{e}");
    }
}
