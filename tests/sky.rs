//! The sky passes against the f64 reference, the reference against closed
//! forms, and the sky at the edges of its parameters.

mod common;

use glam::{DVec3, Vec4};
use slicelight::metrics::relative_error;
use slicelight::reference;
use slicelight::render::{self, Backend};
use slicelight::scene::SceneData;
use slicelight::sky::bench::sky_pixels;
use slicelight::sky::reference::SkyReference;
use std::f64::consts::PI;

/// A fisheye sky scene (Rayleigh, Mie and ozone as in scenes/sky_noon.toml)
/// with the sun `zenith_deg` from the zenith, and extra `[sky]` lines.
fn fisheye(size: u32, zenith_deg: f32, extra: &str) -> SceneData {
    common::scene_from_str(&format!(
        r#"
        [camera]
        projection = "fisheye"
        position = [0.0, 0.0, 0.0]
        look_at = [0.0, 1.0, 0.0]
        up = [0.0, 0.0, -1.0]
        resolution = [{size}, {size}]
        [sky]
        sun_zenith_deg = {zenith_deg}
        sun_azimuth_deg = 40.0
        {extra}
        [sky.atmosphere]
        mie = {{ scattering = 3.996e-6, extinction = 4.4356e-6, scale_height_m = 1200.0, g = 0.8 }}
        ozone = {{}}
        "#
    ))
}

fn rgb(image: &[Vec4], pixels: &[u32]) -> Vec<DVec3> {
    pixels.iter().map(|&i| image[i as usize].truncate().as_dvec3()).collect()
}

#[test]
fn reference_matches_closed_forms() {
    // Rayleigh only, sun at the zenith: the zenith optical depth is
    // beta H (1 - exp(-60/8)); looking straight up, every sample sees the
    // sun straight above it, so the sky there is E P(1) tau exp(-tau).
    let data = common::scene_from_str(
        r#"
        [camera]
        position = [0.0, 0.0, 0.0]
        look_at = [0.0, 1.0, 0.0]
        up = [0.0, 0.0, -1.0]
        vfov_deg = 10.0
        resolution = [8, 8]
        [sky]
        sun_zenith_deg = 0.0
        "#,
    );
    let sky = SkyReference::new(&data.sky.params, 1e-9);
    let beta = DVec3::new(5.802e-6, 13.558e-6, 33.1e-6);
    let beta = beta.as_vec3().as_dvec3(); // the f32 the scene holds
    let tau = beta * 8000.0 * (1.0 - (-60.0f64 / 8.0).exp());
    let depth = sky.zenith_depth(0.0);
    let rel = ((depth - tau) / tau).abs().max_element();
    println!("zenith optical depth {depth} vs {tau}: {rel:e}");
    assert!(rel < 1e-8, "{rel:e}");
    let sun = sky.sun_at_observer();
    assert!(((sun - (-tau).exp()) / (-tau).exp()).abs().max_element() < 1e-8, "{sun}");
    // The radiance straight up, less the sun's disk (radiance E / Omega times
    // the same transmittance), against the closed form.
    let radius = 0.2666f64.to_radians();
    let solid_angle = 4.0 * PI * (0.5 * radius).sin().powi(2);
    assert!((data.sky.params.sun_irradiance.w as f64 / solid_angle - 1.0).abs() < 1e-6);
    let disk = (-tau).exp() / data.sky.params.sun_irradiance.w as f64;
    let sky_up = sky.radiance(DVec3::Y) - disk;
    let exact = 3.0 * 2.0 / (16.0 * PI) * tau * (-tau).exp();
    let rel = ((sky_up - exact) / exact).abs().max_element();
    println!("zenith sky {sky_up} vs {exact}: {rel:e}");
    assert!(rel < 1e-6, "{rel:e}");
}

#[test]
fn reference_converges() {
    // Halving the tolerance changes the reference by far less than the 0.5 %
    // the pass is judged against, at the sunset's grazing rays too.
    for zenith in [30.0f32, 89.5, 96.0] {
        let data = fisheye(8, zenith, "");
        let a = SkyReference::new(&data.sky.params, 1e-6);
        let b = SkyReference::new(&data.sky.params, 1e-8);
        let mut worst = 0.0f64;
        let mut peak = 0.0f64;
        for el in [-3.0f64, -0.2, 0.0, 0.3, 2.0, 10.0, 45.0, 89.0] {
            for az in [0.0f64, 45.0, 140.0, 220.0, 300.0] {
                let (e, z) = (el.to_radians(), az.to_radians());
                let d = DVec3::new(e.cos() * z.sin(), e.sin(), e.cos() * z.cos());
                let (ra, rb) = (a.radiance(d), b.radiance(d));
                worst = worst.max((ra - rb).abs().max_element());
                peak = peak.max(rb.max_element());
            }
        }
        println!("sun {zenith}: tolerance 1e-6 vs 1e-8: {:.2e} of the peak", worst / peak);
        assert!(worst / peak < 1e-4, "sun {zenith}: {:e}", worst / peak);
    }
}

/// The issue's target: within 0.5 % RMS of the sky's peak (sun's disk
/// excluded), every sun angle from the zenith to 6 degrees below the
/// horizon, with the default settings (sky-view table) and integrated per
/// pixel: three tests of three angles each (all nine took 39 s alone).
#[test]
fn sky_matches_reference_with_the_sun_high() {
    sky_matches_reference_for_sun_zeniths(&[0.0, 30.0, 60.0]);
}

#[test]
fn sky_matches_reference_with_the_sun_low() {
    sky_matches_reference_for_sun_zeniths(&[80.0, 88.0, 90.0]);
}

#[test]
fn sky_matches_reference_with_the_sun_below_the_horizon() {
    sky_matches_reference_for_sun_zeniths(&[92.0, 94.0, 96.0]);
}

fn sky_matches_reference_for_sun_zeniths(zeniths: &[f32]) {
    // Every other pixel in x and y of the 48x48 fisheye (the reference's
    // quadrature is the test's cost): the lattice still spans the whole
    // hemisphere, zenith to horizon, in steps of 3.75 degrees.
    for &zenith in zeniths {
        let data = fisheye(48, zenith, "");
        let pixels = sky_pixels(&data, 2);
        let (refvals, _) = reference::render_converged_at(&data, &pixels, 2e-4);
        for (mode, per_pixel) in [("sky-view table", false), ("per pixel", true)] {
            let data = if per_pixel {
                data.reconfigure(move |f| f.sky.as_mut().expect("a [sky]").sky_view = false).unwrap()
            } else {
                data.clone()
            };
            let (image, _) = render::render(&data, &Backend::Cpu, false).unwrap();
            let values = rgb(&image, &pixels);
            assert!(values.iter().all(|v| v.is_finite() && v.min_element() >= 0.0));
            let (rms, max) = relative_error(&values, &refvals);
            println!(
                "sun zenith {zenith:>4}, {mode:<14}: rms {:.3}% max {:.2}% of the sky's peak",
                rms * 100.0,
                max * 100.0
            );
            assert!(rms < 0.005, "sun {zenith}, {mode}: rms {:.3}%", rms * 100.0);
        }
    }
}

/// The sun lights surfaces with its irradiance after the air it crosses,
/// and the sky with its own light (the irradiance table times the share of
/// the sky that 8 rays find): the rendered surfaces of sun_garden match the
/// reference, whose skylight is the hemisphere integral of the f64 sky
/// over 2304 directions with a shadow ray each.
#[test]
fn sunlit_scene_matches_reference() {
    let data = slicelight::scene::load(&common::root().join("scenes/sun_garden.toml")).unwrap();
    // 72x48 (the reference's 2304 skylight rays per pixel are the cost; at
    // 96x64 the error was 0.32 % with 8 rays, 0.09 % with 64); the same
    // objects, shadows and sky are seen.
    let spaced = |rays: u32, light: bool, spacing: u32| {
        data.reconfigure(move |f| {
            f.camera.resolution = [72, 48];
            let sky = f.sky.as_mut().unwrap();
            sky.sky_light_rays = rays;
            sky.sky_light = light;
            sky.sky_light_spacing = spacing;
        })
        .unwrap()
    };
    let small = |rays: u32, light: bool| spaced(rays, light, 2);
    let shaded = small(8, true);
    assert!(shaded.lights.len() == 1, "the sun is the scene's one light");
    let all: Vec<u32> = (0..shaded.pixel_count()).collect();
    let (refvals, _) = reference::render_converged_at(&shaded, &all, 2e-4);
    let measure = |d: &SceneData| {
        let (image, _) = render::render(d, &Backend::Cpu, false).unwrap();
        slicelight::metrics::difference(&rgb(&image, &all), &refvals, d.exposure)
    };
    let d = measure(&shaded);
    let unshadowed = measure(&small(0, true));
    let none = measure(&small(8, false));
    let everywhere = measure(&spaced(8, true, 1));
    let sparse = measure(&spaced(8, true, 8));
    println!(
        "sun_garden 72x48 vs reference: {d:?}\n  unshadowed skylight: {unshadowed:?}\n  no skylight: {none:?}\n  \
         visibility traced at every pixel: {everywhere:?}\n  at one pixel in 8x8: {sparse:?}"
    );
    // The visibility traced at one pixel in 2x2 (the default) and taken by
    // the others where they see the same surface (docs/sky.md): within a
    // tenth of an 8-bit level's RMS of tracing it at every pixel; and even
    // one in 8x8 (the limit) stays within the skylight's own error.
    assert!(d.rms_8bit_percent < everywhere.rms_8bit_percent + 0.1, "{d:?} {everywhere:?}");
    assert!(sparse.rms_8bit_percent < 1.0 && (sparse.energy_ratio - 1.0).abs() < 0.01, "{sparse:?}");
    // Surfaces with exact shadow rays, the sky's table, and the skylight's
    // 8 visibility rays: about one 8-bit level.
    assert!(d.rms_8bit_percent < 0.6, "{d:?}");
    assert!((d.energy_ratio - 1.0).abs() < 0.01, "{d:?}");
    // What the skylight and its shadow add: without them the error is larger
    // (measured: 0.38 % with 8 rays, 1.17 % unshadowed, 1.68 % and energy
    // 0.960 without skylight).
    assert!(unshadowed.rms_8bit_percent > 1.5 * d.rms_8bit_percent, "{unshadowed:?}");
    assert!(none.rms_8bit_percent > 3.0 * d.rms_8bit_percent && none.energy_ratio < 0.98, "{none:?}");
}

#[test]
fn glass_shows_the_sky_through_it_and_in_it() {
    // `glass_garden`: a glass ball and a tinted glass knot under the sky.
    // Where a view through the glass leaves it for the sky, and where the
    // glass reflects the sky, `sky.glass` adds it, and the sky's light on
    // the lawn and the box seen through the glass; the reference follows
    // the same rays in f64 with its own sky quadrature and hemisphere
    // integral. Caustics off on both sides (the reference's light tracer is
    // measured with them).
    let data = slicelight::scene::load(&common::root().join("scenes/glass_garden.toml")).unwrap();
    let data = data
        .reconfigure(|f| {
            f.camera.resolution = [72, 48];
            f.caustics.enabled = false;
        })
        .unwrap();
    let all: Vec<u32> = (0..data.pixel_count()).collect();
    let (refvals, _) = reference::render_converged_at(&data, &all, 2e-4);
    let layer = |data: &SceneData| {
        let r = render::render_layers(data, &Backend::Cpu, false).unwrap();
        let glass = r
            .layers
            .iter()
            .find(|(n, _)| *n == "sky.glass")
            .expect("the sky.glass layer")
            .1
            .as_slice::<Vec4>()
            .to_vec();
        (r.image, glass)
    };
    let (image, glass) = layer(&data);
    // The same layer without the skylight (`sky_light = false`): the sky
    // through and in the glass alone, so the difference is the skylight on
    // what is seen through the glass.
    let (_, glass_unlit) = layer(&data.reconfigure(|f| f.sky.as_mut().unwrap().sky_light = false).unwrap());
    let without: Vec<Vec4> = image.iter().zip(&glass).map(|(a, b)| *a - *b).collect();
    let unlit: Vec<Vec4> = image.iter().zip(&glass).zip(&glass_unlit).map(|((a, b), c)| *a - *b + *c).collect();
    let d = slicelight::metrics::difference(&rgb(&image, &all), &refvals, data.exposure);
    let before = slicelight::metrics::difference(&rgb(&without, &all), &refvals, data.exposure);
    println!("glass_garden 72x48 vs reference: {d:?}\n  without the sky in the glass: {before:?}");
    // Measured: see docs/sky.md ("The sky in glass"). The rest is the
    // skylight's 8 visibility rays on the lawn (about 0.4 % in sun_garden)
    // and glass edges, where f32 and f64 paths part.
    assert!(d.rms_8bit_percent < 1.0, "{d:?}");
    assert!((d.energy_ratio - 1.0).abs() < 0.02, "{d:?}");
    // Without it the glass is black where it shows the sky.
    assert!(before.rms_8bit_percent > 3.0 * d.rms_8bit_percent, "{before:?}");
    // Over the pixels that see glass, with and without the skylight on
    // what lies behind it.
    let seen: Vec<u32> = all.iter().copied().filter(|&i| glass[i as usize].max_element() > 0.0).collect();
    let pick = |v: &[DVec3]| seen.iter().map(|&i| v[i as usize]).collect::<Vec<_>>();
    let on_glass = slicelight::metrics::difference(&rgb(&image, &seen), &pick(&refvals), data.exposure);
    let on_glass_unlit = slicelight::metrics::difference(&rgb(&unlit, &seen), &pick(&refvals), data.exposure);
    println!(
        "  over the {} glass pixels: {on_glass:?}\n  without the skylight behind the glass: {on_glass_unlit:?}",
        seen.len()
    );
    assert!(on_glass.rms_8bit_percent < 2.0 && (on_glass.energy_ratio - 1.0).abs() < 0.03, "{on_glass:?}");
    assert!(on_glass_unlit.rms_8bit_percent > 2.0 * on_glass.rms_8bit_percent, "{on_glass_unlit:?}");
}

/// Stress: observer at 0 m, 10 km and 100 km (looking at the limb), the sun
/// from the zenith to 10 degrees below the horizon, Rayleigh scattering
/// times 0 and times 100: no NaN or Inf, nothing negative; and the 100 km
/// view of the limb still agrees with the reference.
#[test]
fn sky_is_finite_at_the_edges() {
    for altitude in [0.0f32, 10_000.0, 100_000.0] {
        for scale in [0.0f32, 1.0, 100.0] {
            for zenith in [0.0f32, 90.0, 90.01, 100.0] {
                let beta = [5.802e-6 * scale, 13.558e-6 * scale, 33.1e-6 * scale];
                let data = common::scene_from_str(&format!(
                    r#"
                    [camera]
                    position = [0.0, 0.0, 0.0]
                    look_at = [1.0, -0.15, 0.0]
                    vfov_deg = 40.0
                    resolution = [48, 32]
                    [sky]
                    sun_zenith_deg = {zenith}
                    sun_azimuth_deg = 90.0
                    observer_altitude_m = {altitude}
                    [sky.atmosphere]
                    rayleigh_scattering = [{}, {}, {}]
                    mie = {{}}
                    "#,
                    beta[0], beta[1], beta[2]
                ));
                let (image, _) = render::render(&data, &Backend::Cpu, false).unwrap();
                assert!(
                    image.iter().all(|p| p.is_finite() && p.min_element() >= 0.0),
                    "altitude {altitude}, x{scale}, sun {zenith}"
                );
                if scale == 1.0 && zenith == 0.0 {
                    let pixels = sky_pixels(&data, 1);
                    let (refvals, _) = reference::render_converged_at(&data, &pixels, 2e-4);
                    let (rms, _) = relative_error(&rgb(&image, &pixels), &refvals);
                    println!("altitude {altitude}: rms {:.3}% of the peak", rms * 100.0);
                    assert!(rms < 0.01, "altitude {altitude}: {rms}");
                }
            }
        }
    }
}

/// A 1x1 image and an 8192x4096 fisheye: the kernels at the smallest and a
/// very large pixel count stay finite and non-negative.
#[test]
fn sky_at_tiny_and_huge_image_sizes() {
    for (w, h) in [(1u32, 1u32), (8192, 4096)] {
        let data = fisheye(8, 45.0, "").reconfigure(move |f| f.camera.resolution = [w, h]).unwrap();
        let (image, _) = render::render(&data, &Backend::Cpu, false).unwrap();
        assert_eq!(image.len(), (w * h) as usize);
        assert!(image.iter().all(|p| p.is_finite() && p.min_element() >= 0.0), "{w}x{h}");
        let lit = image.iter().filter(|p| p.max_element() > 0.0).count();
        // The image circle covers pi/4 of a square, pi/8 of a 2:1 image.
        println!("{w}x{h}: {lit} pixels of sky");
        assert!(lit >= 1);
    }
}

#[test]
fn bad_sky_fields_are_named() {
    let cases = [
        ("sun_zenith_deg = 200.0", "sky.sun_zenith_deg"),
        ("sun_zenith_deg = 10.0\nsky_view_table = [64, 63]", "sky.sky_view_table"),
        ("sun_zenith_deg = 10.0\nground_albedo = [0.1, 2.0, 0.1]", "sky.ground_albedo"),
        ("sun_zenith_deg = 10.0\n[sky.atmosphere]\ntop_radius_m = 6000.0", "sky.atmosphere.top_radius_m"),
        ("sun_zenith_deg = 10.0\n[sky.atmosphere]\nmie = { g = 1.5 }", "sky.atmosphere.mie.g"),
    ];
    for (sky, field) in cases {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        let toml = format!(
            "[camera]\nposition = [0.0, 0.0, 0.0]\nlook_at = [1.0, 0.0, 0.0]\nvfov_deg = 40.0\nresolution = [8, 8]\n[sky]\n{sky}\n"
        );
        std::fs::write(&path, toml).unwrap();
        let err = format!("{:#}", slicelight::scene::load(&path).unwrap_err());
        println!("{err}");
        assert!(err.contains("bad.toml") && err.contains(field), "{field}: {err}");
    }
    // A fisheye has no field of view, and cannot look through a scattering medium.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fish.toml");
    let fish = "[camera]\nprojection = \"fisheye\"\nposition = [0.0, 0.0, 0.0]\nlook_at = [0.0, 1.0, 0.0]\nup = [0.0, 0.0, 1.0]\nresolution = [8, 8]\n";
    std::fs::write(&path, format!("{fish}vfov_deg = 30.0\n")).unwrap();
    assert!(format!("{:#}", slicelight::scene::load(&path).unwrap_err()).contains("camera.vfov_deg"));
    std::fs::write(&path, format!("{fish}[medium]\nsigma_s = [0.1, 0.1, 0.1]\nsigma_t = [0.1, 0.1, 0.1]\n")).unwrap();
    assert!(format!("{:#}", slicelight::scene::load(&path).unwrap_err()).contains("camera.projection"));
}

/// Aerial perspective: the air's light and transmittance from the eye to a
/// surface `t` metres away (`sky::aerial::aerial_segment`, a midpoint
/// sample per 250 m with the transmittance table) against the f64
/// reference's adaptive quadrature to the same distance, for the sun high,
/// low and below the horizon, views up, level and down, 100 m to 50 km:
/// within 0.5 % of the reference's radiance (the issue's target) and 1e-4
/// of the transmittance.
#[test]
fn aerial_perspective_matches_the_reference_to_the_same_distance() {
    use slicelight::shaders::sky::aerial::aerial_segment;
    use slicelight::shaders::sky::transmittance_texel;
    for zenith in [20.0, 80.0, 93.0] {
        let data = common::scene_from_str(&format!(
            r#"
            [camera]
            position = [0.0, 2.0, 0.0]
            look_at = [0.0, 2.0, -1.0]
            vfov_deg = 40.0
            resolution = [8, 8]
            [sky]
            sun_zenith_deg = {zenith}
            sun_azimuth_deg = 30.0
            [sky.atmosphere]
            mie = {{}}
            ozone = {{}}
            "#
        ));
        let p = data.sky.params;
        let table: Vec<Vec4> =
            (0..p.transmittance_width * p.transmittance_height).map(|i| transmittance_texel(i, &p)).collect();
        let reference = SkyReference::new(&p, 1e-7);
        let mut worst = (0.0f64, 0.0f64);
        for (elevation, azimuth) in [(5.0f64, 0.0f64), (0.5, 100.0), (-2.0, 200.0), (30.0, 300.0)] {
            let (e, a) = (elevation.to_radians(), azimuth.to_radians());
            let d = DVec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos());
            for t in [100.0, 1000.0, 10_000.0, 50_000.0] {
                let (l, through) = aerial_segment(&p, &table, d.as_vec3(), t as f32);
                let (l_ref, through_ref) = reference.segment(d, t);
                let peak = l_ref.max_element().max(1e-30);
                let err = (l.as_dvec3() - l_ref).abs().max_element() / peak;
                let terr = (through.as_dvec3() - through_ref).abs().max_element();
                worst = (worst.0.max(err), worst.1.max(terr));
                assert!(
                    err < 5e-3 || peak < 1e-12,
                    "sun {zenith}, view {elevation}/{azimuth}, {t} m: {err:.2e} ({l:?} vs {l_ref:?})"
                );
                assert!(
                    terr < 1e-4,
                    "sun {zenith}, view {elevation}/{azimuth}, {t} m: transmittance {through:?} vs {through_ref:?}"
                );
            }
        }
        println!(
            "sun at {zenith} degrees: worst {:.3} % of the air's light, {:.1e} of the transmittance",
            100.0 * worst.0,
            worst.1
        );
    }
}
