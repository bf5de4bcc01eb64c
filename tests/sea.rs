//! The sea passes against the f64 references (quadrature and Monte Carlo,
//! which first agree with each other), and the sea at the edges of its
//! parameters.

mod common;

use glam::{DVec3, Vec3};
use slicelight::passes::sea::order2_by_maps;
use slicelight::scene::SceneData;
use slicelight::sea_reference::SeaReference;
use slicelight_shaders::sea::{order1_radiance, SeaParams};

/// Clear ocean water (scenes/README's preset) under a sun `sun_zenith`
/// degrees from the zenith, with extra `[sea]` lines.
fn sea(sun_zenith: f32, extra: &str) -> SceneData {
    common::scene_from_str(&format!(
        r#"
        [camera]
        position = [0.0, 10.0, 0.0]
        look_at = [0.0, 0.0, -20.0]
        vfov_deg = 50.0
        resolution = [48, 32]
        [sky]
        sun_zenith_deg = {sun_zenith}
        sun_azimuth_deg = 30.0
        [sea]
        absorption = [0.343, 0.0585, 0.0180]
        scattering = [0.0369, 0.0489, 0.0620]
        {extra}
        "#
    ))
}

/// Upward directions of travel in the water toward an eye whose view is
/// `air_zenith` degrees from the nadir, `azimuth` degrees from the sun's.
fn in_water(p: &SeaParams, air_zenith: f32, azimuth: f32) -> Vec3 {
    let n = p.extinction.w;
    let sin_w = air_zenith.to_radians().sin() / n;
    let s = p.sun_in_water.truncate();
    let h = Vec3::new(s.x, 0.0, s.z);
    let t = if h.length_squared() > 1e-12 { h.normalize() } else { Vec3::X };
    let u = Vec3::new(-t.z, 0.0, t.x);
    let a = azimuth.to_radians();
    ((t * a.cos() + u * a.sin()) * sin_w + Vec3::Y * (1.0 - sin_w * sin_w).sqrt()).normalize()
}

fn relative(got: DVec3, want: DVec3) -> f64 {
    ((got - want).abs() / want.abs().max(DVec3::splat(1e-300))).max_element()
}

#[test]
fn monte_carlo_and_quadrature_agree_on_orders_1_and_2() {
    for (sun, extra) in [(30.0, ""), (70.0, "depth_m = 15.0\ng = 0.5")] {
        let data = sea(sun, extra);
        let p = &data.sea.params;
        let r = SeaReference::new(p, 1e-5);
        for (zenith, azimuth) in [(0.0, 0.0), (60.0, 180.0)] {
            let view = in_water(p, zenith, azimuth).as_dvec3();
            let (o1, o2) = (r.order1(view), r.order2(view));
            let mc = r.monte_carlo(view, 1_000_000, 7, 10_000);
            println!(
                "sun {sun} view {zenith}/{azimuth}: o1 {o1:?} MC {:?}, o2 {o2:?} MC {:?} +- {:?}, all orders MC {:?}",
                mc.order1, mc.order2, mc.order2_error, mc.all
            );
            // Four standard errors, and 0.3 % for the quadrature's own tolerance.
            for ch in 0..3 {
                assert!(
                    (o1[ch] - mc.order1[ch]).abs() <= 4.0 * mc.order1_error[ch] + 3e-3 * o1[ch],
                    "order 1, channel {ch}"
                );
                assert!(
                    (o2[ch] - mc.order2[ch]).abs() <= 4.0 * mc.order2_error[ch] + 3e-3 * o2[ch],
                    "order 2, channel {ch}"
                );
            }
        }
    }
}

#[test]
fn each_term_is_within_one_percent_of_the_reference_for_a_flat_sea() {
    let mut worst = [0.0f64; 3];
    for sun in [0.0f32, 30.0, 60.0, 80.0] {
        for extra in ["", "depth_m = 20.0"] {
            let data = sea(sun, extra);
            let p = &data.sea.params;
            let r = SeaReference::new(p, 1e-5);
            let views: Vec<Vec3> =
                [0.0f32, 35.0, 70.0].iter().flat_map(|&z| [0.0f32, 90.0, 180.0].map(|a| in_water(p, z, a))).collect();
            let maps = order2_by_maps(p, &views);
            for (view, o2) in views.iter().zip(maps) {
                let v = view.as_dvec3();
                let o1 = order1_radiance(p, *view, p.depth, p.order1_extinction.truncate()).as_dvec3();
                let bottom = slicelight_shaders::sea::bottom_radiance(p, *view, p.depth, p.sun_in_water.w).as_dvec3();
                let errors = [
                    relative(o1, r.order1(v)),
                    relative(o2.as_dvec3(), r.order2(v)),
                    if extra.is_empty() { 0.0 } else { relative(bottom, r.bottom(v)) },
                ];
                for k in 0..3 {
                    worst[k] = worst[k].max(errors[k]);
                }
                println!(
                    "sun {sun} {extra:16} view {view:.3}: order1 {:.3} %, order2 {:.3} %, bottom {:.3} %",
                    100.0 * errors[0],
                    100.0 * errors[1],
                    100.0 * errors[2]
                );
            }
        }
    }
    println!(
        "worst: order1 {:.3} %, order2 {:.3} %, bottom {:.3} %",
        100.0 * worst[0],
        100.0 * worst[1],
        100.0 * worst[2]
    );
    assert!(worst.iter().all(|&e| e < 0.01), "{worst:?}");
}
