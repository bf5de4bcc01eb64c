//! Light at a smooth interface between two dielectrics: Snell's law and
//! Fresnel's equations for unpolarised light. The one copy of both, for
//! the glass (caustics, surfaces seen through glass), the sea's surface, and
//! the f64 references on the host: the scalar laws are generic over the
//! float type, so the references call the same functions at `f64`.
//!
//! Conventions: `cos_i` is the cosine of the angle of incidence (between the
//! ray reversed and the normal on the incident side), in [0, 1] (values
//! outside are clamped); `eta = n_i / n_t` is the index of the incident side
//! over that of the transmitted side (dimensionless).

use crate::glam::Vec3;
use spirv_std::num_traits::Float;

/// Snell's law, `n_i sin(theta_i) = n_t sin(theta_t)`: the cosine of the
/// angle of transmission, `cos_t = sqrt(1 - eta^2 (1 - cos_i^2))`, and
/// whether there is a transmitted ray (false past the critical angle: total
/// internal reflection, where `cos_t` is returned as 0).
pub fn transmitted_cosine<F: Float>(cos_i: F, eta: F) -> (F, bool) {
    let one = F::one();
    let cos_i = cos_i.max(F::zero()).min(one);
    let sin2_t = eta * eta * (one - cos_i * cos_i).max(F::zero());
    if sin2_t >= one {
        return (F::zero(), false);
    }
    ((one - sin2_t).sqrt(), true)
}

/// Fresnel's equations for unpolarised light: the reflected fraction of the
/// power, `R = (r_s^2 + r_p^2) / 2` with
/// `r_s = (eta cos_i - cos_t) / (eta cos_i + cos_t)` and
/// `r_p = (cos_i - eta cos_t) / (cos_i + eta cos_t)`; 1 past the critical
/// angle. Dimensionless, in [0, 1].
pub fn reflectance<F: Float>(cos_i: F, eta: F) -> F {
    let one = F::one();
    let half = (one + one).recip();
    let (cos_t, transmitted) = transmitted_cosine(cos_i, eta);
    if !transmitted {
        return one;
    }
    let cos_i = cos_i.max(F::zero()).min(one);
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    (rs * rs + rp * rp) * half
}

/// The transmitted fraction of the power, `1 - R` (0 past the critical
/// angle), in [0, 1].
pub fn transmittance<F: Float>(cos_i: F, eta: F) -> F {
    (F::one() - reflectance(cos_i, eta)).max(F::zero()).min(F::one())
}

/// The mirror direction of unit `d` about unit normal `n`: `d - 2 (n . d) n`.
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * (2.0 * n.dot(d))
}

/// Snell's law in vector form: the unit direction refracted from unit `d`
/// at a surface of unit normal `n` facing against `d` (`n . d < 0`),
/// `eta d + (eta cos_i - cos_t) n`. Returns it and true, or the mirror
/// direction and false under total internal reflection.
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> (Vec3, bool) {
    let cos_i = (-n.dot(d)).clamp(0.0, 1.0);
    let (cos_t, transmitted) = transmitted_cosine(cos_i, eta);
    if !transmitted {
        return (reflect(d, n), false);
    }
    ((d * eta + n * (eta * cos_i - cos_t)).normalize(), true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_closed_forms() {
        // Normal incidence: R = ((n - 1)/(n + 1))^2 from either side.
        for n in [1.333f32, 1.5] {
            let normal = ((n - 1.0) / (n + 1.0)).powi(2);
            assert!((reflectance(1.0, 1.0 / n) - normal).abs() < 1e-7);
            assert!((reflectance(1.0, n) - normal).abs() < 1e-7, "reciprocal at normal incidence");
        }
        assert!((transmittance(1.0f32, 1.0 / 1.5) - 0.96).abs() < 1e-6);
        // Grazing incidence reflects everything.
        assert_eq!(reflectance(0.0f32, 1.0 / 1.333), 1.0);
        // Past the critical angle (41.8 degrees from glass of 1.5 into air).
        assert_eq!(reflectance(45f32.to_radians().cos(), 1.5), 1.0);
        assert_eq!(transmittance(45f32.to_radians().cos(), 1.5), 0.0);
        assert!(transmittance(40f32.to_radians().cos(), 1.5) > 0.0);
        // Brewster's angle, tan(theta_B) = n: r_p = 0, so R = r_s^2 / 2.
        let n = 1.5f64;
        let brewster = n.atan();
        let cos_t = (1.0 - (brewster.sin() / n).powi(2)).sqrt();
        let rs = (brewster.cos() / n - cos_t) / (brewster.cos() / n + cos_t);
        assert!((reflectance(brewster.cos(), 1.0 / n) - rs * rs / 2.0).abs() < 1e-15);
    }

    #[test]
    fn f32_and_f64_agree() {
        // The references call the same law at f64: the two precisions agree
        // to f32's rounding. Near the critical angle cos_t = sqrt(1 - sin2_t)
        // magnifies sin2_t's rounding (1e-7) without bound, so the check keeps
        // to cos_t >= 0.1, where it is at most 1e-7 / (2 * 0.1) = 5e-7 and R
        // moves by a few times that.
        let mut next = crate::test_uniforms(7);
        for _ in 0..10_000 {
            let cos_i = next();
            let eta = 0.5 + next();
            let (cos_t, transmitted) = transmitted_cosine(cos_i as f64, eta as f64);
            if !transmitted || cos_t < 0.1 {
                continue;
            }
            let r32 = reflectance(cos_i, eta) as f64;
            let r64 = reflectance(cos_i as f64, eta as f64);
            assert!((r32 - r64).abs() < 1e-5, "cos_i {cos_i}, eta {eta}: {r32} against {r64}");
        }
    }

    #[test]
    fn refraction_obeys_snell() {
        let n = Vec3::Y;
        for deg in [0.0f32, 10.0, 30.0, 60.0, 89.0] {
            let a = deg.to_radians();
            let d = Vec3::new(a.sin(), -a.cos(), 0.0);
            let (t, ok) = refract(d, n, 1.0 / 1.5);
            assert!(ok);
            assert!((t.length() - 1.0).abs() < 1e-6);
            let sin_t = t.x;
            assert!((a.sin() - 1.5 * sin_t).abs() < 1e-5, "{deg} degrees");
        }
        // From glass into air past the critical angle: the mirror direction.
        let d = Vec3::new(0.8, -0.6, 0.0);
        let (r, ok) = refract(d, n, 1.5);
        assert!(!ok);
        assert!((r - Vec3::new(0.8, 0.6, 0.0)).length() < 1e-6);
    }
}
