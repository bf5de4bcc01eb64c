//! The sky's reference: the same single-scattering integral as the sky
//! kernels (see `shader-crate/src/sky/`), in f64, with no tables and none
//! of their shortcuts: planet-centred vectors instead of the kernels'
//! altitude formulas, every optical depth (to the sun from each sample, and
//! along the view ray) by adaptive Gauss-Kronrod quadrature refined until
//! its error estimate is below the tolerance, and the Earth's shadow found
//! by bisection on the exact test "the sun's ray from here meets the ground"
//! rather than by the kernels' shadow-cylinder formula.

use glam::DVec3;
use slicelight_shaders::sky::{SkyParams, MIE_CORNETTE_SHANKS};
use std::f64::consts::PI;

// The published constants, to the digits they are published with.
#[allow(clippy::excessive_precision)]
/// Gauss-Kronrod 7-15 nodes on [-1, 1] (the non-negative half) and weights.
const XGK: [f64; 8] = [
    0.991455371120812639206854697526329,
    0.949107912342758524526189684047851,
    0.864864423359769072789712788640926,
    0.741531185599394439863864773280788,
    0.586087235467691130294144845693013,
    0.405845151377397166906606412076961,
    0.207784955007898467600689403773245,
    0.000000000000000000000000000000000,
];
#[allow(clippy::excessive_precision)]
const WGK: [f64; 8] = [
    0.022935322010529224963732008058970,
    0.063092092629978553290700663189204,
    0.104790010322250183839876322541518,
    0.140653259715525918745189590510238,
    0.169004726639267902826583426598550,
    0.190350578064785409913256402421014,
    0.204432940075298892414161999234649,
    0.209482141084727828012999174891714,
];
/// Gauss 7-point weights for the odd-indexed Kronrod nodes (1, 3, 5, 7).
#[allow(clippy::excessive_precision)]
const WG: [f64; 4] = [
    0.129484966168869693270611432679082,
    0.279705391489276667901467771423780,
    0.381830050505118944950369775488975,
    0.417959183673469387755102040816327,
];

/// The 15 nodes of `[a, b]`, in increasing order, with Kronrod and Gauss weights.
fn gk_nodes(a: f64, b: f64) -> [(f64, f64, f64); 15] {
    let (c, h) = (0.5 * (a + b), 0.5 * (b - a));
    let mut out = [(0.0, 0.0, 0.0); 15];
    for k in 0..8 {
        let wg = if k % 2 == 1 { WG[k / 2] } else { 0.0 };
        let wg = if k == 7 { WG[3] } else { wg };
        out[k] = (c - h * XGK[k], h * WGK[k], h * wg);
        out[14 - k] = (c + h * XGK[k], h * WGK[k], h * wg);
    }
    out
}

/// `int_a^b f` by adaptive Gauss-Kronrod until the estimated error of each
/// piece is below `rel` of its value (or `floor`).
pub(crate) fn integrate(f: &dyn Fn(f64) -> DVec3, a: f64, b: f64, rel: f64, floor: f64, depth: u32) -> DVec3 {
    let (mut k, mut g) = (DVec3::ZERO, DVec3::ZERO);
    for (t, wk, wg) in gk_nodes(a, b) {
        let v = f(t);
        k += v * wk;
        g += v * wg;
    }
    if (k - g).abs().max_element() <= rel * k.abs().max_element() + floor || depth == 0 {
        return k;
    }
    let m = 0.5 * (a + b);
    integrate(f, a, m, rel, floor * 0.5, depth - 1) + integrate(f, m, b, rel, floor * 0.5, depth - 1)
}

/// The atmosphere and sun of a `SkyParams`, in f64.
pub struct SkyReference {
    ground: f64,
    top: f64,
    rayleigh: DVec3,
    rayleigh_height: f64,
    mie_scattering: f64,
    mie_extinction: f64,
    mie_height: f64,
    mie_g: f64,
    cornette_shanks: bool,
    ozone: DVec3,
    ozone_center: f64,
    ozone_half_width: f64,
    albedo: DVec3,
    sun_irradiance: DVec3,
    sun: DVec3,
    cos_sun_radius: f64,
    sun_solid_angle: f64,
    observer: DVec3,
    /// Relative tolerance of every quadrature.
    pub tolerance: f64,
}

impl SkyReference {
    pub fn new(p: &SkyParams, tolerance: f64) -> SkyReference {
        let ground = p.ground_radius as f64;
        SkyReference {
            ground,
            top: ground + p.atmosphere_height as f64,
            rayleigh: p.rayleigh.truncate().as_dvec3(),
            rayleigh_height: p.rayleigh.w as f64,
            mie_scattering: p.mie.x as f64,
            mie_extinction: p.mie.y as f64,
            mie_height: p.mie.z as f64,
            mie_g: p.mie.w as f64,
            cornette_shanks: p.mie_phase == MIE_CORNETTE_SHANKS,
            ozone: p.ozone.truncate().as_dvec3(),
            ozone_center: p.ozone_center as f64,
            ozone_half_width: p.ozone_half_width as f64,
            albedo: p.ground_albedo.truncate().as_dvec3(),
            sun_irradiance: p.sun_irradiance.truncate().as_dvec3(),
            sun: p.sun_direction.truncate().as_dvec3().normalize(),
            cos_sun_radius: p.sun_direction.w as f64,
            // The scene's definition of the disk: its solid angle as given.
            sun_solid_angle: p.sun_irradiance.w as f64,
            observer: DVec3::new(0.0, ground + p.observer_altitude as f64, 0.0),
            tolerance,
        }
    }

    fn altitude(&self, p: DVec3) -> f64 {
        (p.length() - self.ground).max(0.0)
    }

    fn extinction(&self, p: DVec3) -> DVec3 {
        let h = self.altitude(p);
        let ozone = if self.ozone_half_width > 0.0 {
            (1.0 - (h - self.ozone_center).abs() / self.ozone_half_width).max(0.0)
        } else {
            0.0
        };
        self.rayleigh * (-h / self.rayleigh_height).exp()
            + DVec3::splat(self.mie_extinction * (-h / self.mie_height).exp())
            + self.ozone * ozone
    }

    /// `(beta_R P_R + beta_M P_M)` at `p` for scattering cosine `nu`, 1/(m sr).
    fn scattering(&self, p: DVec3, nu: f64) -> DVec3 {
        let h = self.altitude(p);
        let g = self.mie_g;
        let hg_denominator = (1.0 + g * g - 2.0 * g * nu).powf(1.5);
        let mie_phase = if self.cornette_shanks {
            3.0 * (1.0 - g * g) * (1.0 + nu * nu) / (8.0 * PI * (2.0 + g * g) * hg_denominator)
        } else {
            (1.0 - g * g) / (4.0 * PI * hg_denominator)
        };
        self.rayleigh * (-h / self.rayleigh_height).exp() * (3.0 * (1.0 + nu * nu) / (16.0 * PI))
            + DVec3::splat(self.mie_scattering * (-h / self.mie_height).exp() * mie_phase)
    }

    /// Where the ray `o + t d` (d unit) meets the sphere of `radius` about
    /// the planet's centre: both roots, if any.
    fn sphere(o: DVec3, d: DVec3, radius: f64) -> Option<(f64, f64)> {
        let b = o.dot(d);
        let c = o.length_squared() - radius * radius;
        let disc = b * b - c;
        (disc >= 0.0).then(|| (-b - disc.sqrt(), -b + disc.sqrt()))
    }

    /// The first distance > 0 at which the ray meets the ground, if any.
    fn ground_hit(&self, o: DVec3, d: DVec3) -> Option<f64> {
        let b = o.dot(d);
        let c = o.length_squared() - self.ground * self.ground;
        if c <= 0.0 {
            // On the ground: any ray into it meets it at once.
            return (b < 0.0).then_some(0.0);
        }
        if b >= 0.0 {
            return None;
        }
        let disc = b * b - c;
        (disc >= 0.0).then(|| c / (-b + disc.sqrt()))
    }

    fn in_shadow(&self, p: DVec3) -> bool {
        self.ground_hit(self.lifted(p), self.sun).is_some()
    }

    /// `p`, or where a point below the ground sphere is taken to be: on
    /// the ground over it (an aerial segment's points below the observer's
    /// altitude 0, where the scene's own ground lies; the kernels clamp
    /// such altitudes to 0 the same way). Points on or above the ground
    /// are left exactly as they are.
    fn lifted(&self, p: DVec3) -> DVec3 {
        let r = p.length();
        if r < self.ground {
            p * (self.ground / r.max(1e-300))
        } else {
            p
        }
    }

    /// Optical depth along `o + t d` over `[a, b]`.
    fn depth(&self, o: DVec3, d: DVec3, a: f64, b: f64) -> DVec3 {
        if b <= a {
            return DVec3::ZERO;
        }
        // Split at the lowest point, where the density peaks.
        let lowest = (-o.dot(d)).clamp(a, b);
        let f = |t: f64| self.extinction(o + d * t);
        let floor = 1e-3 * self.tolerance * self.rayleigh.max_element().max(self.mie_extinction) * 1000.0;
        integrate(&f, a, lowest, self.tolerance, floor, 40) + integrate(&f, lowest, b, self.tolerance, floor, 40)
    }

    /// Transmittance of sunlight to `p` (0 in the Earth's shadow).
    fn sun_transmittance(&self, p: DVec3) -> DVec3 {
        let p = self.lifted(p);
        if self.in_shadow(p) {
            return DVec3::ZERO;
        }
        let Some((_, leave)) = Self::sphere(p, self.sun, self.top) else { return DVec3::ONE };
        (-self.depth(p, self.sun, 0.0, leave.max(0.0))).exp()
    }

    /// The view ray's in-scattering over `[a, b]` (a piece wholly lit or
    /// wholly shadowed, `lit`), given the optical depth `tau_a` from the
    /// observer to `a`: adaptive Gauss-Kronrod whose nodes' optical depths
    /// come from a Kronrod rule over `[a, t]`. Returns the radiance (per unit
    /// sun irradiance) and the optical depth to `b`.
    fn piece(&self, d: DVec3, a: f64, b: f64, tau_a: DVec3, lit: bool, depth: u32) -> (DVec3, DVec3) {
        let o = self.observer;
        let nu = d.dot(self.sun);
        let nodes = gk_nodes(a, b);
        let (mut k, mut g) = (DVec3::ZERO, DVec3::ZERO);
        let (mut tk, mut tg) = (DVec3::ZERO, DVec3::ZERO);
        for &(t, wk, wg) in &nodes {
            let sigma = self.extinction(o + d * t);
            tk += sigma * wk;
            tg += sigma * wg;
            if lit {
                let p = o + d * t;
                // Optical depth from a to t by a 15-node rule on [a, t].
                let tau: DVec3 = gk_nodes(a, t).iter().map(|&(s, w, _)| self.extinction(o + d * s) * w).sum();
                let v = self.scattering(p, nu) * self.sun_transmittance(p) * (-(tau_a + tau)).exp();
                k += v * wk;
                g += v * wg;
            }
        }
        let converged = (k - g).abs().max_element() <= self.tolerance * k.abs().max_element() + 1e-18
            && (tk - tg).abs().max_element() <= self.tolerance * tk.abs().max_element().max(1e-9);
        if converged || depth == 0 {
            return (k, tau_a + tk);
        }
        let m = 0.5 * (a + b);
        let (l1, tau_m) = self.piece(d, a, m, tau_a, lit, depth - 1);
        let (l2, tau_b) = self.piece(d, m, b, tau_m, lit, depth - 1);
        (l1 + l2, tau_b)
    }

    /// The sky's radiance along unit view direction `d` (scene frame, y up):
    /// single scattering, the ground's reflection of the direct sun where the
    /// ray meets the ground, and the sun's disk, W/(m^2 sr).
    pub fn radiance(&self, d: DVec3) -> DVec3 {
        self.radiance_with(d, true)
    }

    /// `radiance` without the sun's disk (a reflection that integrates the
    /// disk on its own takes the rest of the sky from here).
    pub fn sky_without_sun(&self, d: DVec3) -> DVec3 {
        self.radiance_with(d, false)
    }

    fn radiance_with(&self, d: DVec3, disk: bool) -> DVec3 {
        let Some((mut radiance, tau, ground)) = self.single_scattering(d, f64::INFINITY, true) else {
            return DVec3::ZERO;
        };
        match ground {
            Some(t) => {
                let g = self.observer + d * t;
                let mu_s = g.normalize().dot(self.sun);
                if mu_s > 0.0 {
                    radiance +=
                        self.albedo / PI * self.sun_irradiance * self.sun_transmittance(g) * (-tau).exp() * mu_s;
                }
            }
            None => {
                if disk && d.dot(self.sun) >= self.cos_sun_radius {
                    radiance += self.sun_irradiance / self.sun_solid_angle * (-tau).exp();
                }
            }
        }
        radiance
    }

    /// The air's light along unit `d` from the observer to distance `t`
    /// (m) and its transmittance (aerial perspective; no ground, no sun's
    /// disk: the scene's surfaces stand in for the ground, and the air
    /// below the observer's altitude 0 is taken as the air at 0).
    pub fn segment(&self, d: DVec3, t: f64) -> (DVec3, DVec3) {
        match self.single_scattering(d, t, false) {
            Some((radiance, tau, _)) => (radiance, (-tau).exp()),
            None => (DVec3::ZERO, DVec3::ONE),
        }
    }

    /// Single scattering along `d` up to `t_max` (or where the ray leaves
    /// the atmosphere or, with `ground`, meets the ground): the radiance,
    /// the optical depth, and the distance to the ground if the ray meets
    /// it before `t_max`.
    fn single_scattering(&self, d: DVec3, t_max: f64, ground: bool) -> Option<(DVec3, DVec3, Option<f64>)> {
        let o = self.observer;
        let (enter, mut leave) = Self::sphere(o, d, self.top)?;
        let enter = enter.max(0.0);
        let ground = if ground { self.ground_hit(o, d).filter(|&t| t <= t_max) } else { None };
        leave = leave.min(t_max);
        if let Some(t) = ground {
            leave = leave.min(t);
        }
        if leave <= enter {
            // No air on the way; the ground (if met at once) still shows.
            return ground.map(|t| (DVec3::ZERO, DVec3::ZERO, Some(t)));
        }
        // Cuts: the lowest point and every change of shadow, found by a scan
        // and bisection on the exact shadow test.
        let mut cuts = vec![enter, (-o.dot(d)).clamp(enter, leave), leave];
        const SCAN: usize = 2048;
        let at = |i: usize| enter + (leave - enter) * i as f64 / SCAN as f64;
        let mut previous = self.in_shadow(o + d * at(0));
        for i in 1..=SCAN {
            let now = self.in_shadow(o + d * at(i));
            if now != previous {
                let (mut lo, mut hi) = (at(i - 1), at(i));
                for _ in 0..80 {
                    let mid = 0.5 * (lo + hi);
                    if self.in_shadow(o + d * mid) == previous {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                cuts.push(0.5 * (lo + hi));
            }
            previous = now;
        }
        cuts.sort_by(f64::total_cmp);
        let mut tau = DVec3::ZERO;
        let mut sum = DVec3::ZERO;
        for w in cuts.windows(2) {
            let (a, b) = (w[0], w[1]);
            if b <= a {
                continue;
            }
            let lit = !self.in_shadow(o + d * (0.5 * (a + b)));
            let (l, tau_b) = self.piece(d, a, b, tau, lit, 40);
            sum += l;
            tau = tau_b;
        }
        Some((sum * self.sun_irradiance, tau, ground))
    }

    /// Optical depth straight up from altitude `h` to the top.
    pub fn zenith_depth(&self, h: f64) -> DVec3 {
        let o = DVec3::new(0.0, self.ground + h, 0.0);
        self.depth(o, DVec3::Y, 0.0, self.top - self.ground - h)
    }

    /// Transmittance of the direct sun to the observer.
    pub fn sun_at_observer(&self) -> DVec3 {
        self.sun_transmittance(self.observer)
    }
}

/// The reference's skylight grid: `(direction, radiance)` at the midpoints
/// of `REFERENCE_AZIMUTHS x REFERENCE_ZENITHS` equal solid angles over the
/// sphere, the radiance by the f64 quadrature (no tables, no sun disk).
pub const REFERENCE_AZIMUTHS: usize = 96;
pub const REFERENCE_ZENITHS: usize = 48;

pub fn sky_light_grid(p: &SkyParams) -> Vec<(DVec3, DVec3)> {
    use rayon::prelude::*;
    let sky = SkyReference::new(p, crate::reference::SKY_TOLERANCE);
    (0..REFERENCE_AZIMUTHS * REFERENCE_ZENITHS)
        .into_par_iter()
        .map(|k| {
            let (i, j) = (k % REFERENCE_AZIMUTHS, k / REFERENCE_AZIMUTHS);
            let mu = -1.0 + 2.0 * (j as f64 + 0.5) / REFERENCE_ZENITHS as f64;
            let phi = std::f64::consts::TAU * (i as f64 + 0.5) / REFERENCE_AZIMUTHS as f64;
            let ring = (1.0 - mu * mu).max(0.0).sqrt();
            let w = DVec3::new(ring * phi.cos(), mu, ring * phi.sin());
            // The sun's disk lights the scene as a directional light: not here.
            let disk = w.dot(sky.sun) >= sky.cos_sun_radius;
            (w, if disk { DVec3::ZERO } else { sky.radiance(w) })
        })
        .collect()
}

/// The skylight's direction grid (`sky_light_grid`), computed once per
/// scene. Call it before a parallel loop over pixels: the first
/// `sky_light` inside one would compute it on one thread while the others
/// wait on the lock (measured: most of `glass_garden`'s reference at
/// 72x48 ran on one core).
pub fn prepare(data: &crate::scene::SceneData) {
    if data.sky.enabled && data.sky.light {
        grid(data);
    }
}

/// The scene's skylight grid, computed the first time it is asked for.
fn grid(data: &crate::scene::SceneData) -> &[(DVec3, DVec3)] {
    data.sky.reference_grid.get_or_init(|| sky_light_grid(&data.sky.params))
}

/// The sky's light reflected by a diffuse surface of `albedo` at `point`
/// (unit `normal`, toward the viewer), f64: `albedo / pi` times the
/// irradiance summed over the grid's directions above the surface that a
/// ray from the point leaves the scene by (against the real geometry).
pub fn sky_light(data: &crate::scene::SceneData, point: DVec3, normal: DVec3, albedo: DVec3) -> DVec3 {
    if !data.sky.enabled || !data.sky.light {
        return DVec3::ZERO;
    }
    let grid = grid(data);
    let scale = point.abs().max_element().max(1.0);
    let solid_angle = 4.0 * std::f64::consts::PI / grid.len() as f64;
    let mut e = DVec3::ZERO;
    for (w, l) in grid {
        let c = normal.dot(*w);
        if c > 0.0 && crate::reference::nearest(data, point, *w, 1e-9 * scale / c.max(1e-3), f64::INFINITY).is_none() {
            e += *l * c;
        }
    }
    albedo * e * solid_angle / std::f64::consts::PI
}
