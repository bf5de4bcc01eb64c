//! The sea passes against the f64 references (quadrature and Monte Carlo,
//! which first agree with each other), and the sea at the edges of its
//! parameters.

mod common;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use slicelight::scene::SceneData;
use slicelight::sea::order2_by_maps;
use slicelight::sea::reference::SeaReference;
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
    // The quadrature's tolerance, 1e-3 relative, is a tenth of the 1 %
    // checked. It was 1e-5: the worst errors found are the same to the
    // printed digit (order 2 0.532 %), in 15 s instead of 82 s on two cores
    // (with the eight cases now run in parallel).
    let cases: Vec<(f32, &str)> =
        [0.0f32, 30.0, 60.0, 80.0].iter().flat_map(|&sun| ["", "depth_m = 20.0"].map(|extra| (sun, extra))).collect();
    let worst = cases
        .par_iter()
        .map(|&(sun, extra)| {
            let mut worst = [0.0f64; 3];
            let data = sea(sun, extra);
            let p = &data.sea.params;
            let r = SeaReference::new(p, 1e-3);
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
            worst
        })
        .reduce(|| [0.0f64; 3], |a, b| [a[0].max(b[0]), a[1].max(b[1]), a[2].max(b[2])]);
    println!(
        "worst: order1 {:.3} %, order2 {:.3} %, bottom {:.3} %",
        100.0 * worst[0],
        100.0 * worst[1],
        100.0 * worst[2]
    );
    assert!(worst.iter().all(|&e| e < 0.01), "{worst:?}");
}

/// Renders on the CPU and checks the image and every layer: finite, not negative.
fn render_checked(data: &SceneData, what: &str) -> slicelight::render::Rendered {
    let r = slicelight::render::render_layers(data, &slicelight::render::Backend::Cpu, false).unwrap();
    for (name, values) in
        std::iter::once(("image", &r.image[..])).chain(r.layers.iter().map(|(n, b)| (*n, b.as_slice::<glam::Vec4>())))
    {
        for v in values {
            assert!(v.is_finite() && v.min_element() >= 0.0, "{what}: {name} holds {v}");
        }
    }
    r
}

fn layer<'a>(r: &'a slicelight::render::Rendered, name: &str) -> &'a [glam::Vec4] {
    r.layers.iter().find(|(n, _)| *n == name).map(|(_, b)| b.as_slice()).unwrap_or(&[])
}

#[test]
fn stress_the_sun_the_views_the_depth_and_the_water_at_their_edges() {
    // Each variant renders 24x16 through every sea pass; nothing may be NaN,
    // infinite or negative.
    let camera = |look: &str| {
        format!(
            r#"
            [camera]
            position = [0.0, 10.0, 0.0]
            look_at = {look}
            vfov_deg = 50.0
            resolution = [24, 16]
            "#
        )
    };
    let water = "absorption = [0.343, 0.0585, 0.0180]\nscattering = [0.0369, 0.0489, 0.0620]";
    let variants: Vec<(&str, String, String)> = vec![
        ("sun at the zenith", "sun_zenith_deg = 0.0".into(), water.into()),
        ("sun on the horizon", "sun_zenith_deg = 89.9".into(), water.into()),
        ("sun below the horizon", "sun_zenith_deg = 95.0".into(), water.into()),
        ("depth 0.01 m", "sun_zenith_deg = 30.0".into(), format!("{water}\ndepth_m = 0.01")),
        ("depth 10 000 m", "sun_zenith_deg = 30.0".into(), format!("{water}\ndepth_m = 10000.0")),
        (
            "no scattering",
            "sun_zenith_deg = 30.0".into(),
            "absorption = [0.3, 0.05, 0.02]\nscattering = [0.0, 0.0, 0.0]\ndepth_m = 5.0".into(),
        ),
        (
            "no absorption",
            "sun_zenith_deg = 30.0".into(),
            "absorption = [0.0, 0.0, 0.0]\nscattering = [0.0369, 0.0489, 0.0620]".into(),
        ),
        (
            "nothing at all",
            "sun_zenith_deg = 30.0".into(),
            "absorption = [0.0, 0.0, 0.0]\nscattering = [0.0, 0.0, 0.0]\ndepth_m = 3.0".into(),
        ),
        ("g = 0", "sun_zenith_deg = 30.0".into(), format!("{water}\ng = 0.0")),
        ("g = 0.999", "sun_zenith_deg = 30.0".into(), format!("{water}\ng = 0.999")),
        ("g = -0.5", "sun_zenith_deg = 30.0".into(), format!("{water}\ng = -0.5")),
        (
            "rough sea",
            "sun_zenith_deg = 60.0".into(),
            format!("{water}\nwaves = {{ kind = \"spectrum\", wind_m_s = 25.0, size_m = 20.0, resolution = 64 }}"),
        ),
    ];
    for (what, sky, sea) in &variants {
        for look in ["[0.0, 0.0, -20.0]", "[0.0, 9.99, -1000.0]"] {
            let t = std::time::Instant::now();
            let data = common::scene_from_str(&format!("{}\n[sky]\n{sky}\n[sea]\n{sea}\n", camera(look)));
            render_checked(&data, &format!("{what}, looking at {look}"));
            println!(
                "{what}: n_z {} n_d {} ({:?})",
                data.sea.params.planes,
                3 * data.sea.params.polar.pow(2),
                t.elapsed()
            );
        }
    }
}

#[test]
fn stress_image_sizes() {
    // 1x1 renders whole; 8192x8192 (1.3 GB of layers) is checked at its
    // corners, edges and centre through the per-pixel kernel functions.
    let scene = |w: u32, h: u32| {
        common::scene_from_str(&format!(
            "[camera]\nposition = [0.0, 10.0, 0.0]\nlook_at = [0.0, 0.0, -20.0]\nvfov_deg = 50.0\nresolution = [{w}, {h}]\n\
             [sky]\nsun_zenith_deg = 40.0\n[sea]\nabsorption = [0.343, 0.0585, 0.0180]\nscattering = [0.0369, 0.0489, 0.0620]\ndepth_m = 12.0\n"
        ))
    };
    let one = render_checked(&scene(1, 1), "1x1");
    assert!(layer(&one, "sea.order1")[0].max_element() > 0.0, "the one pixel sees the sea");
    let big = scene(8192, 8192);
    let p = &big.sea.params;
    let blank = slicelight_shaders::common::surface::no_surface();
    let waves = &big.sea.waves;
    let clouds = slicelight_shaders::sea::CloudShadow { lights: &big.lights, grids: &[], depths: &[] };
    let sunlit = slicelight_shaders::sea::under::Sunlit { shafts: &[], geometry: big.geometry() };
    let n = 8192u32;
    for (x, y) in [(0, 0), (n - 1, 0), (0, n - 1), (n - 1, n - 1), (n / 2, n / 2), (n / 2, n - 1), (0, n / 2)] {
        let i = y * n + x;
        let seen = slicelight_shaders::sea::surface_pixel(i, &big.common, p, waves, &[0.0], &blank);
        assert!(seen.is_finite() && seen.w >= 0.0, "pixel ({x}, {y}): surface {seen}");
        for v in [
            slicelight_shaders::sea::order1_pixel(i, &big.common, p, seen, &big.sea.bottom, &[], &sunlit, &clouds),
            slicelight_shaders::sea::bottom_pixel(
                i,
                &big.common,
                p,
                seen,
                &big.sea.bottom,
                &[],
                &sunlit,
                &big.materials,
                &clouds,
            ),
        ] {
            assert!(v.is_finite() && v.min_element() >= 0.0, "pixel ({x}, {y}): {v}");
        }
        // The lower half of the image looks down at the sea.
        if y > n / 2 + 8 {
            let v =
                slicelight_shaders::sea::order1_pixel(i, &big.common, p, seen, &big.sea.bottom, &[], &sunlit, &clouds);
            assert!(v.max_element() > 0.0, "pixel ({x}, {y}) misses the sea");
        }
    }
}

#[test]
fn albedo_one_water_keeps_every_order_and_the_maps_hold() {
    // No absorption: every scattering event survives, so light leaves only
    // through the surface (or is lost to the deep). Orders 1 and 2 stay
    // finite and within 1 % of the reference; the higher orders, which only
    // the Monte Carlo reference counts, carry most of the light.
    let data = sea(40.0, "");
    let mut p = data.sea.params;
    p.extinction = p.scattering.truncate().extend(p.extinction.w);
    p.order1_extinction = p.extinction;
    p.plane_depth =
        (glam::Vec3::splat(slicelight_shaders::sea::DEEP_OPTICAL_DEPTH) / p.scattering.truncate()).extend(0.0);
    let view = in_water(&p, 20.0, 90.0);
    let r = SeaReference::new(&p, 1e-5);
    let (o1, o2) = (r.order1(view.as_dvec3()), r.order2(view.as_dvec3()));
    let maps = order2_by_maps(&p, &[view])[0].as_dvec3();
    let exact1 = order1_radiance(&p, view, p.depth, p.extinction.truncate()).as_dvec3();
    let mc = r.monte_carlo(view.as_dvec3(), 20_000, 3, 20_000);
    println!("albedo 1: order1 {o1:?}, order2 {o2:?}, all orders (MC) {:?}; all / order1 {:?}", mc.all, mc.all / o1);
    assert!(
        relative(exact1, o1) < 1e-3 && relative(maps, o2) < 0.01,
        "order 1 {exact1:?} vs {o1:?}, order 2 {maps:?} vs {o2:?}"
    );
    assert!((mc.all / (o1 + o2)).min_element() > 2.0, "the higher orders carry most of the light");
}

#[test]
fn eq5_as_printed_against_the_orders_it_stands_for() {
    // The measurement behind the default (`single = "exact"`): eq. 5 as
    // printed, beside the exact order 1, orders 1 + 2, and all orders by
    // Monte Carlo, on clear ocean and coastal water.
    let waters = [
        ("clear ocean", "absorption = [0.343, 0.0585, 0.0180]\nscattering = [0.0369, 0.0489, 0.0620]"),
        ("coastal", "absorption = [0.380, 0.120, 0.280]\nscattering = [0.390, 0.460, 0.560]"),
    ];
    for (name, water) in waters {
        let scene = |single: &str| {
            common::scene_from_str(&format!(
                "[camera]\nposition = [0.0, 10.0, 0.0]\nlook_at = [0.0, 0.0, -20.0]\nvfov_deg = 50.0\nresolution = [8, 8]\n\
                 [sky]\nsun_zenith_deg = 40.0\n[sea]\n{water}\nsingle = \"{single}\"\nsecond_order = false\n"
            ))
        };
        let (p, printed) = (scene("exact").sea.params, scene("paper-eq5").sea.params);
        let view = in_water(&p, 30.0, 180.0);
        let r = SeaReference::new(&p, 1e-5);
        let (o1, o2) = (r.order1(view.as_dvec3()), r.order2(view.as_dvec3()));
        let eq5 = order1_radiance(&printed, view, printed.depth, printed.order1_extinction.truncate()).as_dvec3();
        let mc = r.monte_carlo(view.as_dvec3(), 400_000, 11, 20_000);
        println!(
            "{name}: eq5 / order 1 = {:.2?}; (eq5 + order 2) / all = {:.2?}; (order 1 + order 2) / all = {:.2?}; all (MC) / order 1 = {:.2?}",
            (eq5 / o1).to_array(),
            ((eq5 + o2) / mc.all).to_array(),
            ((o1 + o2) / mc.all).to_array(),
            (mc.all / o1).to_array()
        );
        assert!((eq5 / o1).min_element() > 1.0, "eq. 5's reduced extinction always adds light");
    }
}

#[test]
fn reference_tolerance_is_converged() {
    // `slicelight reference` and the bench use SEA_TOLERANCE; against a
    // tolerance 100 times tighter its orders 1 and 2 must agree to 1e-3
    // (the accuracy targets are 1 %).
    let data = sea(50.0, "depth_m = 20.0");
    let p = &data.sea.params;
    let (loose, tight) = (
        SeaReference::new(p, slicelight::reference::SEA_TOLERANCE),
        SeaReference::new(p, slicelight::reference::SEA_TOLERANCE / 100.0),
    );
    let mut worst = 0.0f64;
    for (zenith, azimuth) in [(0.0, 0.0), (40.0, 0.0), (70.0, 180.0), (89.0, 90.0)] {
        let v = in_water(p, zenith, azimuth).as_dvec3();
        worst = worst.max(relative(loose.order1(v), tight.order1(v))).max(relative(loose.order2(v), tight.order2(v)));
    }
    println!("SEA_TOLERANCE against 1/100 of it: largest relative difference {worst:e}");
    assert!(worst < 1e-3, "{worst}");
}

/// A scene folder holding `bottom.png` (grey `value(x, y)` over `w x h`) and
/// a sea over it, rendered at 24x16.
fn over_image(w: u32, h: u32, value: impl Fn(u32, u32) -> u8, sea: &str) -> (tempfile::TempDir, SceneData) {
    let dir = tempfile::tempdir().unwrap();
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([value(x, y)])).save(dir.path().join("bottom.png")).unwrap();
    let toml = format!(
        "[camera]\nposition = [0.0, 8.0, 0.0]\nlook_at = [0.0, 0.0, -20.0]\nvfov_deg = 60.0\nresolution = [24, 16]\n\
         [sky]\nsun_zenith_deg = 40.0\n[sea]\nabsorption = [0.343, 0.0585, 0.0180]\nscattering = [0.0369, 0.0489, 0.0620]\n{sea}\n"
    );
    std::fs::write(dir.path().join("scene.toml"), toml).unwrap();
    let data = slicelight::scene::load(&dir.path().join("scene.toml")).unwrap();
    (dir, data)
}

#[test]
fn a_level_height_field_renders_as_the_flat_bottom() {
    // A white image at shallow_m = 10 is a flat bottom 10 m down: the march
    // and its secant are exact on a level bottom, and the shallowest order-2
    // layer is built for exactly that depth.
    let (_dir, field) = over_image(8, 8, |_, _| 255, "bottom = { kind = \"image\", path = \"bottom.png\", size_m = [400.0, 400.0], shallow_m = 10.0, deep_m = 30.0 }");
    let flat = common::scene_from_str(
        "[camera]\nposition = [0.0, 8.0, 0.0]\nlook_at = [0.0, 0.0, -20.0]\nvfov_deg = 60.0\nresolution = [24, 16]\n\
         [sky]\nsun_zenith_deg = 40.0\n[sea]\nabsorption = [0.343, 0.0585, 0.0180]\nscattering = [0.0369, 0.0489, 0.0620]\ndepth_m = 10.0\n",
    );
    let mut flat = flat;
    (flat.sea.params.planes, flat.sea.params.polar, flat.sea.params.azimuths) =
        (field.sea.params.planes, field.sea.params.polar, field.sea.params.azimuths);
    let (a, b) = (render_checked(&field, "level field"), render_checked(&flat, "flat"));
    for (name, tol) in [("sea.order1", 1e-4f32), ("sea.bottom", 1e-4), ("sea.order2", 1e-4), ("sea.reflection", 0.0)] {
        let (x, y) = (layer(&a, name), layer(&b, name));
        assert_eq!(x.len(), y.len(), "{name}");
        let peak = y.iter().fold(0.0f32, |m, v| m.max(v.max_element()));
        assert!(peak > 0.0, "{name} is black");
        let worst = x.iter().zip(y).fold(0.0f32, |m, (p, q)| m.max((*p - *q).abs().max_element()));
        assert!(worst <= tol * peak, "{name}: {worst} of {peak}");
    }
}

#[test]
fn stress_a_bottom_with_cliffs() {
    // Steps from 0.5 m to 60 m every 16 pixels, a lone pillar: no NaN, no
    // infinity, nothing negative, and the shallow squares show brighter
    // bottom than the deep ones.
    let (_dir, data) = over_image(
        64,
        64,
        |x, y| if (x / 16 + y / 16) % 2 == 0 || (x == 40 && y == 40) { 255 } else { 0 },
        "bottom = { kind = \"image\", path = \"bottom.png\", size_m = [40.0, 40.0], center_m = [0.0, -15.0], shallow_m = 0.5, deep_m = 60.0 }",
    );
    assert!(data.sea.params.table_width > 0, "the cliffs render with the depth table");
    let r = render_checked(&data, "cliffs");
    let bottom = layer(&r, "sea.bottom");
    let (lo, hi) = bottom.iter().fold((f32::INFINITY, 0.0f32), |(a, b), v| (a.min(v.y), b.max(v.y)));
    assert!(hi > 10.0 * lo.max(1e-30), "the shallow squares show: {lo} .. {hi}");
}

#[test]
fn shore_against_a_path_tracer_over_the_height_field() {
    // Order 1 is exact given the depth where the view ray meets the bottom
    // (section 5.4); a path tracer over the real height field checks it, at
    // pixels over 1.3 to 5.4 m of water: within 3 % plus 4 of the path
    // tracer's standard errors. Its order 2 (4 million paths a channel leave
    // 2 to 5 %) is checked the same way; the deterministic height-field
    // quadrature below is the sharper judge of order 2.
    let data = slicelight::scene::load(&common::root().join("scenes/sea_shore.toml")).unwrap();
    let data = data.reconfigure(move |f| f.camera.resolution = [72, 48]).unwrap();
    let r = slicelight::render::render_layers(&data, &slicelight::render::Backend::Cpu, false).unwrap();
    let (o1, o2) = (layer(&r, "sea.order1"), layer(&r, "sea.order2"));
    let p = &data.sea.params;
    let grid = &data.sea.bottom;
    let bottom = slicelight::sea::reference::grid_depth(p, grid);
    let reference = SeaReference::new(p, 1e-5);
    let blank = slicelight_shaders::common::surface::no_surface();
    let mut worst = (0.0f64, 0.0f64);
    for y in [26u32, 30, 38, 47] {
        let i = y * 72 + 36;
        let v = slicelight_shaders::sea::sea_view(i, &data.common, p, &data.sea.waves, &blank);
        assert!(v.hit);
        let (depth, _) = slicelight_shaders::sea::bottom_hit(p, grid, v.point.x, v.point.z, v.view);
        let mc = reference.monte_carlo_over(
            v.view.as_dvec3(),
            (v.point.x as f64, v.point.z as f64),
            &bottom,
            4_000_000,
            5,
            20_000,
        );
        let t = v.transmission as f64;
        let (m1, m2) = (o1[i as usize].truncate().as_dvec3() / t, o2[i as usize].truncate().as_dvec3() / t);
        let (e1, e2) = (relative(m1, mc.order1), relative(m2, mc.order2));
        println!(
            "pixel row {y}: bottom {depth:.2} m under the view ray; order 1 {:.2} % off the path tracer (+-{:.2} %), order 2 {:.2} % (+-{:.2} %)",
            100.0 * e1,
            100.0 * (mc.order1_error / mc.order1).max_element(),
            100.0 * e2,
            100.0 * (mc.order2_error / mc.order2).max_element()
        );
        assert!(e1 <= 0.03 + 4.0 * (mc.order1_error / mc.order1).max_element(), "order 1 at row {y}: {e1}");
        assert!(e2 <= 0.03 + 4.0 * (mc.order2_error / mc.order2).max_element(), "order 2 at row {y}: {e2}");
        worst = (worst.0.max(e1), worst.1.max(e2));
    }
    println!("worst: order 1 {:.2} %, order 2 {:.2} %", 100.0 * worst.0, 100.0 * worst.1);
}

#[test]
fn the_height_field_quadrature_over_a_level_bottom_is_the_flat_one() {
    // `order2_over` marches every upward direction to the bottom and ends
    // the view ray where it meets it; over a level field 12 m down that must
    // give the flat slab's order 2 (no march, closed-form spans), within the
    // two quadratures' tolerance (1e-4 each).
    let data = sea(40.0, "depth_m = 12.0");
    let p = &data.sea.params;
    let reference = SeaReference::new(p, 1e-4);
    let level = |_: f64, _: f64| 12.0;
    let field = slicelight::sea::reference::HeightField { depth: &level, step: 0.7, deepest: 12.0 };
    for (zenith, azimuth) in [(0.0, 0.0), (50.0, 30.0), (75.0, 200.0)] {
        let v = in_water(p, zenith, azimuth).as_dvec3();
        let (over, flat) = (reference.order2_over(&field, (3.0, -4.0), v), reference.order2(v));
        println!("view {zenith} deg: over a level field / flat = {:.6?}", (over / flat).to_array());
        assert!(relative(over, flat) < 1e-3, "{over} vs {flat}");
    }
}

#[test]
fn shore_order2_against_the_height_field_quadrature() {
    // The method reads order 2 between maps built for flat bottoms (12
    // depths) at the depth where the view ray meets the bottom, and adds
    // the depth table's correction (section 5.4) for the bottom along every
    // sampling ray. The deterministic quadrature over the real height field
    // (`order2_over`, tolerance 1e-3, converged to 2e-3 against 1e-4 below)
    // judges it on sea_shore's slope of 0.12 m per m, at pixels over 1.3 to
    // 5.4 m of water: at most 1.31 % with the table when this test was
    // written; without it (`depth_table = 0`) 3.8 %, of which the locally
    // flat water alone (the flat quadrature at the view ray's depth) is
    // 2.5 %. Bounds: 2 % with the table, and it must beat no table.
    let data = slicelight::scene::load(&common::root().join("scenes/sea_shore.toml")).unwrap();
    let data = data.reconfigure(move |f| f.camera.resolution = [72, 48]).unwrap();
    let r = slicelight::render::render_layers(&data, &slicelight::render::Backend::Cpu, false).unwrap();
    let o2 = layer(&r, "sea.order2");
    let mut no_table = data.clone();
    (no_table.sea.params.table_width, no_table.sea.params.table_height) = (0, 0);
    let r = slicelight::render::render_layers(&no_table, &slicelight::render::Backend::Cpu, false).unwrap();
    let o2_flat = layer(&r, "sea.order2");
    let p = &data.sea.params;
    assert!(p.table_width > 0, "sea_shore renders with a depth table");
    let grid = &data.sea.bottom;
    let depth = slicelight::sea::reference::grid_depth(p, grid);
    let field = slicelight::sea::reference::HeightField::of_sea(p, &depth);
    let reference = SeaReference::new(p, 1e-3);
    let blank = slicelight_shaders::common::surface::no_surface();
    let pixels = [(36u32, 26u32), (36, 30), (36, 38), (36, 47), (5, 40), (66, 33)];
    let rows: Vec<_> = pixels
        .par_iter()
        .map(|&(x, y)| {
            let i = y * 72 + x;
            let v = slicelight_shaders::sea::sea_view(i, &data.common, p, &data.sea.waves, &blank);
            assert!(v.hit);
            let (d, _) = slicelight_shaders::sea::bottom_hit(p, grid, v.point.x, v.point.z, v.view);
            let start = (v.point.x as f64, v.point.z as f64);
            let exact = reference.order2_over(&field, start, v.view.as_dvec3());
            let flat = SeaReference { depth: d as f64, ..reference.clone() }.order2(v.view.as_dvec3());
            let method = o2[i as usize].truncate().as_dvec3() / v.transmission as f64;
            let without = o2_flat[i as usize].truncate().as_dvec3() / v.transmission as f64;
            (x, y, d, relative(method, exact), relative(without, exact), relative(flat, exact))
        })
        .collect();
    let (mut worst, mut worst_flat) = (0.0f64, 0.0f64);
    for (x, y, d, method, without, flat) in rows {
        println!(
            "pixel ({x}, {y}), bottom {d:.2} m under the view ray, off the height-field quadrature: method {:.2} %, without the depth table {:.2} %, the locally flat quadrature {:.2} %",
            100.0 * method,
            100.0 * without,
            100.0 * flat
        );
        worst = worst.max(method);
        worst_flat = worst_flat.max(without);
    }
    println!("worst: {:.2} % with the depth table, {:.2} % without", 100.0 * worst, 100.0 * worst_flat);
    assert!(worst < 0.02, "{worst}");
    assert!(worst < worst_flat, "the depth table does not help: {worst} against {worst_flat}");
    // The quadrature's own convergence at the shallowest pixel.
    let v = slicelight_shaders::sea::sea_view(47 * 72 + 36, &data.common, p, &data.sea.waves, &blank);
    let start = (v.point.x as f64, v.point.z as f64);
    let (loose, tight) = (
        reference.order2_over(&field, start, v.view.as_dvec3()),
        SeaReference::new(p, 1e-4).order2_over(&field, start, v.view.as_dvec3()),
    );
    println!("tolerance 1e-3 against 1e-4: {:.2e}", relative(loose, tight));
    assert!(relative(loose, tight) < 2e-3);
}

/// `sea_open` (Fig. 9b) seen through a 480x82 window just below its
/// horizon at the scene's own pixel size (0.104 degrees, as its 720x480
/// view), rendered at `spp` samples per pixel with the wave filter on or off.
fn horizon_window(filter: bool, spp: u32) -> (Vec<glam::Vec4>, Vec<glam::Vec4>, u32, u32, f32) {
    let text = std::fs::read_to_string(common::root().join("scenes/sea_open.toml")).unwrap();
    let rest = text[text.find("[sky]").unwrap()..].replace("seed = 1 }", &format!("seed = 1, filter = {filter} }}"));
    assert!(rest.contains("filter = "), "sea_open's waves line changed");
    let (width, height) = (480u32, 82u32);
    let mut data = common::scene_from_str(&format!(
        "[camera]\nposition = [0.0, 12.0, 0.0]\nlook_at = [0.0, {}, -60.0]\nvfov_deg = {}\nresolution = [{width}, {height}]\nexposure = 8.0\n{rest}",
        12.0 - 60.0 * 4.0f32.to_radians().tan(),
        50.0 / 480.0 * height as f32,
    ));
    data = data.reconfigure(move |f| f.camera.samples_per_pixel = spp).unwrap();
    let r = render_checked(&data, &format!("filter {filter}, {spp} spp"));
    (r.image.clone(), layer(&r, "sea.order1").to_vec(), width, height, data.exposure)
}

#[test]
fn filtered_waves_at_one_sample_match_sixty_four_near_the_horizon() {
    // Issue 26's target: with the slopes filtered by each sample's
    // footprint, one sample per pixel matches 64 within 1 % RMS of the
    // 8-bit range where a pixel covers many waves. Compared below the
    // first row that sees only sea: the horizon's own row is the sky's
    // edge, antialiasing's business, not the waves' (4 % there either way).
    let (one, seen, w, h, exposure) = horizon_window(true, 1);
    let (many, _, _, _, _) = horizon_window(true, 64);
    let (raw_one, _, _, _, _) = horizon_window(false, 1);
    let (raw_many, _, _, _, _) = horizon_window(false, 64);
    let first = slicelight::sea::bench_waves::first_sea_row(&seen, w, h).unwrap();
    let band = ((first + 1) * w) as usize..(w * h) as usize;
    assert!(band.len() >= (w * 60) as usize, "the window shows {} rows of sea", h - first);
    let rms = |a: &[glam::Vec4], b: &[glam::Vec4]| {
        let (a, b) = (slicelight::metrics::to_f64(&a[band.clone()]), slicelight::metrics::to_f64(&b[band.clone()]));
        slicelight::metrics::difference(&a, &b, exposure).rms_8bit_percent
    };
    let (filtered, unfiltered, converged) = (rms(&one, &many), rms(&raw_one, &raw_many), rms(&many, &raw_many));
    println!(
        "rows {}..{h} below the horizon: 1 spp against 64 spp, filtered {filtered:.2} %, point-sampled {unfiltered:.2} %; \
         the two at 64 spp {converged:.2} % apart",
        first + 1
    );
    assert!(filtered < 1.0, "filtered: {filtered:.2} % RMS (8-bit)");
    // Point samples there pick one wave of hundreds: the sparkle the
    // filter removes is several times the filtered error.
    assert!(unfiltered > 3.0 * filtered, "point-sampled {unfiltered:.2} % against filtered {filtered:.2} %");
    // At 64 spp both approach the pixel's mean; the point samples are
    // still noisy there (64 of hundreds of waves), so 2 %.
    assert!(converged < 2.0, "filtered and point-sampled at 64 spp: {converged:.2} % apart");
}

#[test]
fn the_rough_reflection_matches_the_f64_reference() {
    // The reflected sky and sun of sea_open's waves at pixel centres, the
    // slopes read at each point (`filter = false`: the reference takes the
    // same points), against `sea::reference::rough_reflection`: f64, a
    // 24 x 6 product rule over the full 2D Gaussian of the roughness, the
    // sky by its own quadrature and the sun's disk integrated by half
    // vectors; 64 pixels, 32 of them on the sea (its sky costs ~0.6 s a pixel). Where
    // the glint dominates the two agree within 0.1 %; the reflected sky
    // differs by up to 7 % in red and blue near the horizon (the method
    // takes each node's mean slope across the view and reads the sky from
    // its table; the reference integrates across with 6 nodes): measured
    // 2.2 % RMS, 6.6 % at worst over 144 pixels. Held at 3 % and 8 %.
    let text = std::fs::read_to_string(common::root().join("scenes/sea_open.toml")).unwrap();
    let rest = text[text.find("[sky]").unwrap()..].replace("seed = 1 }", "seed = 1, filter = false }");
    let data = common::scene_from_str(&format!(
        "[camera]\nposition = [0.0, 12.0, 0.0]\nlook_at = [0.0, 6.0, -60.0]\nvfov_deg = 50.0\nresolution = [48, 32]\n{rest}"
    ));
    let r = render_checked(&data, "sea_open at 48x32");
    let reflection = layer(&r, "sea.reflection");
    let p = &data.sea.params;
    let sky = slicelight::sky::reference::SkyReference::new(&data.sky.params, slicelight::reference::SKY_TOLERANCE);
    let pixels: Vec<u32> = (0..32u32).step_by(4).flat_map(|y| (0..48u32).step_by(6).map(move |x| y * 48 + x)).collect();
    let errors: Vec<(u32, f64)> = pixels
        .par_iter()
        .filter_map(|&i| {
            let (origin, dir) = slicelight_shaders::camera::camera_ray(&data.common, i % 48, i / 48);
            if dir.y >= 0.0 {
                return None;
            }
            let hit = origin + dir * ((p.level - origin.y) / dir.y);
            let normal = slicelight_shaders::sea::surface_normal(p, &data.sea.waves, hit.x, hit.z).as_dvec3();
            let slope = glam::DVec2::new(-normal.x / normal.y, -normal.z / normal.y);
            let (want, _) = slicelight::sea::reference::rough_reflection(
                &sky,
                &data.sky.params,
                dir.as_dvec3(),
                slope,
                p.roughness.truncate().as_dvec3(),
                p.extinction.w as f64,
                glam::DVec3::ONE,
                &|_| None,
            );
            let got = reflection[i as usize].truncate().as_dvec3();
            Some((i, ((got - want).length() / want.length().max(1e-300))))
        })
        .collect();
    assert!(errors.len() >= 32, "{} pixels see the sea", errors.len());
    let rms = (errors.iter().map(|e| e.1 * e.1).sum::<f64>() / errors.len() as f64).sqrt();
    let worst = errors.iter().cloned().fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    println!("{} pixels: RMS {:.2} %, worst {:.2} % at pixel {}", errors.len(), 100.0 * rms, 100.0 * worst.1, worst.0);
    assert!(rms < 0.03 && worst.1 < 0.08, "RMS {rms}, worst {worst:?}");
}

/// Issue 26, objects under the water seen from above: a diffuse quad 2 m
/// down in flat water 30 m deep is, to the eye above, what a flat bottom 2
/// m down of the same albedo is. `sea.bottom` (the object's reflection of
/// the refracted sun, attenuated up to the surface) and `sea.order1` (the
/// water's single scattering, now ended at the object) must agree with the
/// bottom's closed forms at every pixel centre the quad covers, within
/// f32 rounding of the two paths' depths (the object's is its hit distance
/// times the refracted ray's cosine): 1e-4 of each layer's peak. And the
/// quad's own light in air, which the straight view ray would see through
/// the water, is taken out (`sea.water` is 0 there). Order 2 is left out:
/// its maps hold the deep bottom's light (see docs/sea.md).
/// Issue 26: an object under waves seen from above takes the waves'
/// caustic at its depth, as the bottom does there. A quad 2 m down in water
/// 30 m deep against a flat bottom 2 m down, under the same waves: the
/// quad's caustic comes from the shaft planes (built for an eye above the
/// water because an object reaches under it; here one plane lies at 2 m
/// and the planes' maps have the wave map's resolution), the bottom's from
/// its own map; both are the same triangles cut at the same depth, so they
/// agree but for the f32 depth of the quad's points. The caustic's own
/// contrast on the quad (against `shafts = false`, the flat beam) is what
/// the comparison would miss by if the quad took no caustic.
#[test]
fn an_object_under_waves_takes_the_caustic_at_its_depth() {
    let waves = "waves = { kind = \"spectrum\", wind_m_s = 6.0, size_m = 16.0, resolution = 64, seed = 5 }";
    let scene = |depth: &str, object: &str, extra: &str| {
        format!("bottom_albedo = [0.6, 0.5, 0.3]\n{waves}\nshaft_planes = 3\nshaft_depth_m = 4.0\n{extra}\n{depth}\n{object}")
    };
    let quad = "[[object]]\ntype = \"quad\"\ncenter = [0.0, -2.0, -10.0]\nu = [60.0, 0.0, 0.0]\nv = [0.0, 0.0, 40.0]\nalbedo = [0.6, 0.5, 0.3]";
    let with_object = sea(40.0, &scene("depth_m = 30.0", quad, ""));
    let with_bottom = sea(40.0, &scene("depth_m = 2.0", "", ""));
    let flat_beam = sea(40.0, &scene("depth_m = 30.0", quad, "shafts = false"));
    assert_eq!(with_object.sea.params.shaft_planes, 3, "no shaft planes for an object under the water");
    assert_eq!(with_bottom.sea.params.shaft_planes, 0, "shaft planes without an object or a varying bottom");
    let (a, b, c) = (
        render_checked(&with_object, "object"),
        render_checked(&with_bottom, "bottom"),
        render_checked(&flat_beam, "flat beam"),
    );
    let (x, y, z) = (layer(&a, "sea.bottom"), layer(&b, "sea.bottom"), layer(&c, "sea.bottom"));
    let (w, h) = (with_object.width(), with_object.height());
    let peak = y.iter().fold(0.0f32, |m, v| m.max(v.truncate().max_element()));
    let (mut worst, mut contrast, mut covered) = (0.0f32, 0.0f32, 0);
    for i in 0..(w * h) as usize {
        // The lower half of the image sees the water over the quad.
        if (i as u32) / w < h / 2 + 2 {
            continue;
        }
        covered += 1;
        worst = worst.max((x[i] - y[i]).truncate().abs().max_element() / peak);
        contrast = contrast.max((z[i] - y[i]).truncate().abs().max_element() / peak);
    }
    println!("{covered} pixels: the quad against the bottom {worst:.2e} of the peak; the flat beam against the bottom {contrast:.3}");
    assert!(covered > 500 && contrast > 0.05, "the waves focus nothing here ({contrast:.3}): the test shows nothing");
    // 1e-3: the quad's points lie within f32 rounding of 2 m, where the
    // planes are read between their two neighbours along the sun.
    assert!(worst <= 1e-3, "the quad's caustic is {worst:.3e} of the peak off the bottom's at its depth");
}

#[test]
fn an_object_under_flat_water_is_the_bottom_at_its_depth() {
    // `sea`'s clear ocean water, sun 40 degrees from the zenith; the extra
    // lines go into `[sea]`, then the objects.
    let scene = |depth: &str, object: &str| format!("bottom_albedo = [0.6, 0.5, 0.3]\n{depth}\n{object}");
    let quad = "[[object]]\ntype = \"quad\"\ncenter = [0.0, -2.0, -10.0]\nu = [60.0, 0.0, 0.0]\nv = [0.0, 0.0, 40.0]\nalbedo = [0.6, 0.5, 0.3]";
    let with_object = sea(40.0, &scene("depth_m = 30.0", quad));
    let with_bottom = sea(40.0, &scene("depth_m = 2.0", ""));
    // The same quad 1 cm above the water: lit in air (the layers are as
    // the image holds them, after each transmittance).
    let above = sea(40.0, &scene("depth_m = 30.0", &quad.replace("-2.0, -10.0", "0.01, -10.0")));
    let lit_in_air = layer(&render_checked(&above, "above"), "surface").to_vec();
    let a = render_checked(&with_object, "object");
    let b = render_checked(&with_bottom, "bottom");
    let (w, h) = (with_object.width(), with_object.height());
    // The image over the quad is the sea's layers alone: the quad's light
    // in air (the surface pass's, the sky's on it) is attenuated to 0.
    let in_air = layer(&a, "surface");
    let sea: Vec<&[glam::Vec4]> =
        a.layers.iter().filter(|(n, _)| n.starts_with("sea.")).map(|(_, b)| b.as_slice()).collect();
    for name in ["sea.bottom", "sea.order1"] {
        let (x, y) = (layer(&a, name), layer(&b, name));
        let peak = y.iter().fold(0.0f32, |m, v| m.max(v.truncate().max_element()));
        assert!(peak > 0.0, "{name}: the bottom's layer is dark");
        let mut worst = 0.0f32;
        let mut covered = 0;
        for i in 0..(w * h) as usize {
            // The lower half of the image sees the water over the quad.
            if (i as u32) / w < h / 2 + 2 {
                continue;
            }
            covered += 1;
            let seen = sea.iter().fold(glam::Vec3::ZERO, |m, l| m + l[i].truncate());
            let image = a.image[i].truncate();
            assert!(lit_in_air[i].truncate().max_element() > 0.0, "pixel {i}: the quad above the water is dark");
            assert_eq!(in_air[i], glam::Vec4::ZERO, "pixel {i}: the quad's light in air is left in");
            assert!(
                (image - seen).abs().max_element() <= 1e-5 * image.max_element().max(1e-6),
                "pixel {i}: the image {image} is not the sea's layers {seen}: the quad's light in air is left in"
            );
            worst = worst.max((x[i] - y[i]).truncate().abs().max_element() / peak);
        }
        println!("{name}: {covered} pixels, worst difference {worst:.2e} of the peak {peak:.3e}");
        assert!(covered > 500 && worst <= 1e-4, "{name}: {worst:.3e} of the peak");
    }
}

/// `sea_glass` with a flat sea (order 2 and the caustic off, so that the
/// reference costs seconds, not minutes): over the pixels that see glass,
/// against `slicelight reference`, which follows the same rays in f64 to
/// its own sea (`sea_radiance`) and sky. `sea.glass` draws the sea along
/// the rays that leave the glass downward (and the sea the glass
/// reflects); without it those pixels were dark. Measured: see
/// docs/sea.md ("The sea in glass").
#[test]
fn glass_over_the_sea_shows_the_sea() {
    use glam::Vec4;
    use slicelight::render::{self, Backend};
    let data = slicelight::scene::load(&common::root().join("scenes/sea_glass.toml"))
        .unwrap()
        .reconfigure(|f| {
            f.camera.resolution = [36, 24];
            let sea = f.sea.as_mut().unwrap();
            sea.waves = slicelight::sea::Waves::Flat;
            sea.second_order = false;
            sea.caustics = false;
        })
        .unwrap();
    let r = render::render_layers(&data, &Backend::Cpu, false).unwrap();
    let layer = |name: &str| r.layers.iter().find(|(n, _)| *n == name).expect(name).1.as_slice::<Vec4>().to_vec();
    let (sea, sky) = (layer("sea.glass"), layer("sky.glass"));
    let seen: Vec<u32> =
        (0..data.pixel_count()).filter(|&i| (sea[i as usize] + sky[i as usize]).max_element() > 0.0).collect();
    assert!(seen.len() > 40, "{} glass pixels", seen.len());
    let (refvals, _) = slicelight::reference::render_converged_at(&data, &seen, 1e-3);
    let pick = |image: &[Vec4]| seen.iter().map(|&i| image[i as usize].truncate().as_dvec3()).collect::<Vec<DVec3>>();
    let without: Vec<Vec4> = r.image.iter().zip(&sea).map(|(a, b)| *a - *b).collect();
    let d = slicelight::metrics::difference(&pick(&r.image), &refvals, data.exposure);
    let before = slicelight::metrics::difference(&pick(&without), &refvals, data.exposure);
    println!("sea_glass (flat) over {} glass pixels: {d:?}\n  without sea.glass: {before:?}", seen.len());
    assert!(d.rms_8bit_percent < 0.5 && (d.energy_ratio - 1.0).abs() < 0.01, "{d:?}");
    assert!(before.rms_8bit_percent > 3.0 * d.rms_8bit_percent, "{before:?}");
}

/// How well `sea.reflection` (and `sea.glass_air` where there is glass)
/// mirrors an object over the sea, flat and under waves.
struct Mirrored {
    name: &'static str,
    pixels: usize,
    d: slicelight::metrics::Difference,
    rms: f64,
    worst: f64,
}

/// The scene's `object` (TOML) over sea_open's sea (an eye 6 m above the
/// water looking 40 m out; flat water and sea_open's waves, the slopes read
/// at each point, `filter = false`): the reflection layers at pixel
/// centres against the f64 reflection at the same points, a flat sea's
/// mirror or `rough_reflection` over its 24 x 6 slopes, each reflected ray
/// traced (`reference::seen_in_air`: opaque objects lit by shadow rays and
/// the sky's grid, glass traced through), the sun's glint where the object
/// does not hide the sun (`reference::sun_over_water`). Over the pixels
/// whose reflection the object changes by more than 5 %, or whose mirror
/// direction at the mean slope meets it in f64; not those that see the
/// object itself (`sees`: the camera ray's origin and direction).
fn mirrored_against_f64(
    object: &str,
    seas: &[&str],
    every: usize,
    sees: impl Fn(Vec3, Vec3) -> bool + Sync,
) -> Vec<Mirrored> {
    let text = std::fs::read_to_string(common::root().join("scenes/sea_open.toml")).unwrap();
    let rest = text[text.find("[sky]").unwrap()..].replace("seed = 1 }", "seed = 1, filter = false }");
    let camera = "[camera]\nposition = [0.0, 6.0, 0.0]\nlook_at = [0.0, 0.0, -40.0]\nvfov_deg = 40.0\nresolution = [32, 24]\nexposure = 8.0";
    let flat = rest.replace("waves = {", "waves = { kind = \"flat\" }\n# waves = {");
    let mut out = Vec::new();
    for (name, sea) in [("flat", &flat), ("waves", &rest)] {
        if !seas.contains(&name) {
            continue;
        }
        let with = common::scene_from_str(&format!("{camera}\n{sea}\n{object}"));
        let without = common::scene_from_str(&format!("{camera}\n{sea}"));
        let reflection = |r: &slicelight::render::Rendered| -> Vec<glam::Vec4> {
            let glass = layer(r, "sea.glass_air");
            let mirror = layer(r, "sea.reflection");
            mirror.iter().enumerate().map(|(i, v)| *v + glass.get(i).copied().unwrap_or_default()).collect()
        };
        let got = reflection(&render_checked(&with, name));
        let open = reflection(&render_checked(&without, name));
        let p = &with.sea.params;
        let sky = slicelight::sky::reference::SkyReference::new(&with.sky.params, slicelight::reference::SKY_TOLERANCE);
        let n = p.extinction.w as f64;
        let ray = |i: u32| slicelight_shaders::camera::camera_ray(&with.common, i % 32, i / 32);
        let mirrors_object = |i: u32| {
            let (o, d) = ray(i);
            let (o, d) = (o.as_dvec3(), d.as_dvec3());
            let hit = o + d * ((p.level as f64 - o.y) / d.y);
            let normal = slicelight_shaders::sea::surface_normal(p, &with.sea.waves, hit.x as f32, hit.z as f32);
            let normal =
                if p.waves == slicelight_shaders::sea::WAVES_NORMAL_MAP { normal.as_dvec3() } else { DVec3::Y };
            let mirror = (d - normal * (2.0 * d.dot(normal))).normalize();
            d.y < 0.0 && mirror.y > 0.0 && slicelight::reference::seen_in_air(&with, hit, mirror).is_some()
        };
        let pixels: Vec<u32> = (0..with.pixel_count())
            .filter(|&i| {
                let (g, o) = (got[i as usize].truncate(), open[i as usize].truncate());
                let (origin, dir) = ray(i);
                !sees(origin, dir) && ((g - o).abs().max_element() > 0.05 * o.max_element() || mirrors_object(i))
            })
            .collect();
        let candidates = pixels.len();
        let pixels: Vec<u32> = pixels.into_iter().step_by(every).collect();
        let clock = std::time::Instant::now();
        let pairs: Vec<(DVec3, DVec3)> = pixels
            .par_iter()
            .map(|&i| {
                let (origin, dir) = ray(i);
                let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
                let hit = o + d * ((p.level as f64 - o.y) / d.y);
                let objects = |w: DVec3| slicelight::reference::seen_in_air(&with, hit, w);
                let want = if p.waves == slicelight_shaders::sea::WAVES_NORMAL_MAP {
                    let normal =
                        slicelight_shaders::sea::surface_normal(p, &with.sea.waves, hit.x as f32, hit.z as f32);
                    let normal = normal.as_dvec3();
                    let slope = glam::DVec2::new(-normal.x / normal.y, -normal.z / normal.y);
                    let shade = DVec3::splat(slicelight::reference::sun_over_water(&with, hit));
                    let rough = p.roughness.truncate().as_dvec3();
                    let params = &with.sky.params;
                    slicelight::sea::reference::rough_reflection(&sky, params, d, slope, rough, n, shade, &objects).0
                } else {
                    let reflected = DVec3::new(d.x, -d.y, d.z);
                    let r = slicelight_shaders::optics::reflectance(-d.y, 1.0 / n);
                    objects(reflected).unwrap_or_else(|| sky.radiance(reflected)) * r
                };
                (got[i as usize].truncate().as_dvec3(), want)
            })
            .collect();
        let errors: Vec<f64> = pairs.iter().map(|(g, w)| (*g - *w).length() / w.length().max(1e-300)).collect();
        let (g, w): (Vec<DVec3>, Vec<DVec3>) = pairs.iter().cloned().unzip();
        let d = slicelight::metrics::difference(&g, &w, with.exposure);
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
        let worst = errors.iter().cloned().fold(0.0, f64::max);
        println!(
            "{name}: {} of the {candidates} pixels that mirror the object (reference {:.1} s): 8-bit RMS {:.3} %, \
             max {:.3} %, energy {:.4}; relative RMS {:.2} %, worst {:.2} %",
            pixels.len(),
            clock.elapsed().as_secs_f64(),
            d.rms_8bit_percent,
            d.max_8bit_percent,
            d.energy_ratio,
            100.0 * rms,
            100.0 * worst
        );
        out.push(Mirrored { name, pixels: pixels.len(), d, rms, worst });
    }
    out
}

/// A post standing on the water's surface at the middle of the view,
/// mirrored by the sea (`mirrored_against_f64`).
#[test]
fn objects_over_the_sea_are_mirrored_in_it() {
    let post =
        "[[object]]\ntype = \"box\"\nmin = [-1.5, 0.0, -42.0]\nmax = [1.5, 9.0, -40.0]\nalbedo = [0.7, 0.55, 0.4]";
    let sees_post = |o: Vec3, d: Vec3| {
        let (lo, hi) = (Vec3::new(-1.5, 0.0, -42.0), Vec3::new(1.5, 9.0, -40.0));
        let (a, b) = ((lo - o) / d, (hi - o) / d);
        a.min(b).max_element() <= a.max(b).min_element()
    };
    for Mirrored { name, pixels, d, rms, worst } in mirrored_against_f64(post, &["flat", "waves"], 1, sees_post) {
        assert!(pixels >= 8, "{name}: the post is mirrored in {pixels} pixels");
        if name == "flat" {
            // Measured 0.09 % at every pixel (f32 against f64 and the sky's
            // table against its quadrature).
            assert!(rms < 0.005 && worst < 0.01, "{name}: RMS {rms}, worst {worst}");
        } else {
            // Measured over 58 pixels: 1.32 % RMS (8-bit), 5.1 % at most,
            // energy 0.989; 10.8 % RMS relative, 29 % at worst (the edges
            // of the blurred reflection, where it is small). The method's 8
            // nodes along the view against the reference's 24, 3 across
            // against 6. With the node's mean slope across alone: 2.94 %,
            // 7.5 %, energy 0.859.
            assert!(d.rms_8bit_percent < 2.0 && d.max_8bit_percent < 8.0, "{name}: {d:?}");
            assert!((d.energy_ratio - 1.0).abs() < 0.03, "{name}: {d:?}");
        }
    }
}

/// A glass ball (radius 3 m, index 1.5) floating 1 m over flat water at
/// the middle of the view, mirrored by the sea with what it shows (the sky
/// and the sun bent through it, the sky it mirrors, the sea seen back
/// through its underside): `sea.reflection` sees nothing where its rays
/// meet the glass, `sea.glass_air` the glass (`mirrored_against_f64`, the
/// reference tracing the glass in f64). Flat water here; under waves,
/// `glass_over_waves_is_mirrored_in_it` (slow: `#[ignore]`, a step of its own in `.ci/run`).
#[test]
fn glass_over_the_sea_is_mirrored_in_it() {
    let (ball, sees_ball) = glass_ball_over_the_sea();
    for Mirrored { name, pixels, d, rms, worst } in mirrored_against_f64(ball, &["flat"], 1, sees_ball) {
        assert!(pixels >= 8, "{name}: the ball is mirrored in {pixels} pixels");
        // Measured over 16 pixels: 0.09 % RMS relative, 0.18 % at worst
        // (f32 against f64), as the post's mirror; without the sea seen
        // back through the ball's underside (rays that leave the glass
        // downward) the lowest row was 60-97 % dark.
        assert!(rms < 0.005 && worst < 0.01, "{name}: RMS {rms}, worst {worst}, {d:?}");
    }
}

/// The glass ball of `glass_over_the_sea_is_mirrored_in_it` (TOML), and
/// whether a camera ray (origin, direction) sees it.
fn glass_ball_over_the_sea() -> (&'static str, impl Fn(Vec3, Vec3) -> bool + Sync) {
    let ball = "[[object]]\ntype = \"sphere\"\ncenter = [0.0, 4.0, -41.0]\nradius = 3.0\nmaterial = { kind = \"glass\", ior = 1.5 }";
    let sees_ball = |o: Vec3, d: Vec3| {
        let c = Vec3::new(0.0, 4.0, -41.0) - o;
        let along = c.dot(d);
        along > 0.0 && (c - d * along).length() <= 3.0
    };
    (ball, sees_ball)
}

/// The same glass ball mirrored by sea_open's waves, at every 8th of the
/// pixels that mirror it (8 of 57). Not in the default run: the reference
/// follows each of its 273 rays per pixel (24 x 6 slopes, 128 directions
/// of the sun's disk) through the glass, and each one that leaves the
/// glass downward into a rough sea of its own, with its own 273 rays and
/// the sea's second order in f64: 352 to 450 s for the 8 pixels on the 2-core
/// machine. `.ci/run` runs it after the other tests (`cargo test --release
/// --workspace -- --ignored`); by hand, `cargo test --release --test sea --
/// --ignored --nocapture glass_over_waves`.
#[test]
#[ignore = "slow: about 6 minutes of f64 reference on 2 cores"]
fn glass_over_waves_is_mirrored_in_it() {
    let (ball, sees_ball) = glass_ball_over_the_sea();
    for Mirrored { name, pixels, d, .. } in mirrored_against_f64(ball, &["waves"], 8, sees_ball) {
        assert!(pixels >= 6, "{name}: the ball is mirrored in {pixels} pixels");
        // Measured 2.95 % RMS (8-bit), 6.7 % at most, energy 0.982; the
        // post's bounds (2 %, 8 %, 3 %) plus what the glass adds: its
        // image through the ball, sharper than the post's faces, seen by
        // the method's 8 x 3 nodes against the reference's 24 x 6, and the
        // sun's disk seen through the glass, which the method leaves out
        // over waves (the reference's slope rays that find it).
        assert!(d.rms_8bit_percent < 4.0 && d.max_8bit_percent < 10.0, "{name}: {d:?}");
        assert!((d.energy_ratio - 1.0).abs() < 0.04, "{name}: {d:?}");
    }
}
