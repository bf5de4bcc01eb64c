//! Phase functions, each normalised so that its integral over the sphere is 1
//! (unit: 1/sr). The scattering strength lives in the medium's `sigma_s`.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::types::{PHASE_DOBASHI, PHASE_HENYEY_GREENSTEIN, PHASE_RAYLEIGH};
use core::f32::consts::PI;

/// Isotropic scattering: `1 / (4 pi)`, 1/sr.
pub fn isotropic() -> f32 {
    1.0 / (4.0 * PI)
}

/// Henyey-Greenstein phase function, 1/sr (eq. 3 of the 2000 sea paper):
/// `(1 - g^2) / (4 pi (1 + g^2 - 2 g cos_theta)^(3/2))`, where `cos_theta` is
/// the cosine of the angle between the incident travel direction and the
/// scattered travel direction (`g > 0` is forward scattering).
///
/// At `|g| -> 1` the denominator of the peak goes to 0 like `(1 - g)^3`; it
/// is written as `(1 - g)^2 + 2 g (1 - cos_theta)` so that the difference is not
/// taken between two numbers near 1.
pub fn henyey_greenstein(cos_theta: f32, g: f32) -> f32 {
    let one_minus_g = 1.0 - g;
    let denom = one_minus_g * one_minus_g + 2.0 * g * (1.0 - cos_theta);
    let denom = denom.max(1e-30);
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())
}

/// Rayleigh phase function, 1/sr: `3 (1 + cos^2) / (16 pi)` (eq. 1 of the
/// survey's sky section uses the un-normalised `1 + cos^2`).
pub fn rayleigh(cos_theta: f32) -> f32 {
    3.0 * (1.0 + cos_theta * cos_theta) / (16.0 * PI)
}

/// The 2002 shafts-of-light paper's phase function `K (1 + 9 cos^16(a/2))`
/// (eq. 4), with `K = 1 / (8 pi)` so that it integrates to 1 over the sphere:
/// `cos^2(a/2) = (1 + cos a) / 2`, and `int (1 + 9 ((1+mu)/2)^8) 2 pi dmu = 8 pi`.
/// `cos_theta` is the cosine of the phase angle `a`, 1/sr.
pub fn dobashi(cos_theta: f32) -> f32 {
    let c2 = (0.5 * (1.0 + cos_theta)).max(0.0);
    let c4 = c2 * c2;
    let c8 = c4 * c4;
    let c16 = c8 * c8;
    (1.0 + 9.0 * c16) / (8.0 * PI)
}

/// The angular width of the phase function's sharpest feature, radians: the
/// scale on which it may change by a large factor. Henyey-Greenstein's peak
/// is `1 - |g|` wide (`(1-g)^2 + 2g(1 - cos a)` doubles at `a ~ (1-g)/sqrt(g)`);
/// the 2002 function's `cos^16(a/2) ~ exp(-2 a^2)` is about 0.7 wide;
/// Rayleigh and isotropic scattering vary over a radian or more.
pub fn angular_scale(kind: u32, g: f32) -> f32 {
    if kind == PHASE_HENYEY_GREENSTEIN {
        (1.0 - g.abs()).max(1e-3)
    } else if kind == PHASE_DOBASHI {
        0.7
    } else {
        1.0
    }
}

/// The phase function chosen by `kind` (a `PHASE_*` constant), 1/sr.
pub fn evaluate(kind: u32, cos_theta: f32, g: f32) -> f32 {
    if kind == PHASE_HENYEY_GREENSTEIN {
        henyey_greenstein(cos_theta, g)
    } else if kind == PHASE_RAYLEIGH {
        rayleigh(cos_theta)
    } else if kind == PHASE_DOBASHI {
        dobashi(cos_theta)
    } else {
        isotropic()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::PHASE_ISOTROPIC;

    /// Integral over the sphere, `2 pi int_{-1}^{1} p(mu) dmu`, in f64 by the
    /// composite Simpson rule on `n` intervals (with the substitution that
    /// spreads nodes toward `mu = 1` for the peaked functions).
    fn sphere_integral(kind: u32, g: f32, n: usize) -> f64 {
        // mu = 1 - 2 x^4 packs nodes near the forward peak; dmu = 8 x^3 dx.
        let f = |x: f64| {
            let mu = 1.0 - 2.0 * x.powi(4);
            evaluate(kind, mu as f32, g) as f64 * 8.0 * x.powi(3)
        };
        let a = 0.0;
        let b = 1.0;
        let h = (b - a) / n as f64;
        let mut s = f(a) + f(b);
        for i in 1..n {
            s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        2.0 * std::f64::consts::PI * s * h / 3.0
    }

    #[test]
    fn every_phase_function_integrates_to_one() {
        // Simpson on 20000 panels is exact to ~1e-9 for smooth integrands; the
        // f32 evaluation of p limits the sum to about 1e-6 relative.
        for (kind, g) in [(PHASE_ISOTROPIC, 0.0), (PHASE_RAYLEIGH, 0.0), (PHASE_DOBASHI, 0.0)] {
            let i = sphere_integral(kind, g, 20_000);
            assert!((i - 1.0).abs() < 1e-5, "kind {kind}: {i}");
        }
        for g in [-0.9, -0.5, 0.0, 0.3, 0.8, 0.95] {
            let i = sphere_integral(PHASE_HENYEY_GREENSTEIN, g, 20_000);
            assert!((i - 1.0).abs() < 1e-4, "HG g={g}: {i}");
        }
    }

    #[test]
    fn henyey_greenstein_stays_finite_at_the_edges() {
        for g in [-0.999_f32, 0.999] {
            for mu in [-1.0_f32, -0.5, 0.0, 0.999, 1.0] {
                let p = henyey_greenstein(mu, g);
                assert!(p.is_finite() && p >= 0.0, "g={g} mu={mu}: {p}");
            }
        }
        // Peak value in closed form: (1+g) / (4 pi (1-g)^2).
        let g = 0.999_f32;
        let peak = (1.0 + g as f64) / (4.0 * std::f64::consts::PI * (1.0 - g as f64).powi(2));
        let rel = (henyey_greenstein(1.0, g) as f64 - peak).abs() / peak;
        assert!(rel < 1e-3, "rel {rel}");
    }

    #[test]
    fn dobashi_matches_the_paper_shape() {
        // Forward peak is 10x the value at right angles... times cos^16(45deg)=1/256.
        let ratio = dobashi(1.0) / dobashi(0.0);
        let expected = 10.0 / (1.0 + 9.0 / 256.0);
        assert!((ratio - expected).abs() < 1e-5);
    }
}
