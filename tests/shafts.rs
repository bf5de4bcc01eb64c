//! The shafts-of-light pass against the f64 reference ray march, its
//! convergence in planes and sub-planes, and its numerical stability at the
//! edges of its parameters (CPU backend; the GPU runs the same functions and
//! is compared in equivalence.rs).

mod common;

use glam::{DVec3, Vec4};
use slicelight::common::surface::SurfaceShadows;
use slicelight::metrics::{difference, to_f64, Difference};
use slicelight::reference;
use slicelight::render::{self, Backend};
use slicelight::scene::{SceneData, ShaftMode};

fn render_cpu(data: &SceneData) -> Vec<Vec4> {
    render::render(data, &Backend::Cpu, false).unwrap().0
}

fn with_shafts(data: &SceneData, planes: u32, subplanes: u32, mode: ShaftMode, jitter: bool) -> SceneData {
    data.reconfigure(move |f| {
        let s = &mut f.shafts;
        s.planes = planes;
        s.subplanes = subplanes;
        s.mode = mode;
        s.jitter = jitter;
    })
    .unwrap()
}

/// The Fig. 6 scene at 180x120: a coarser grid of pixel centres than the
/// shipped 720x480, shared by the method and the reference.
fn fig6_small() -> SceneData {
    let text = std::fs::read_to_string(common::root().join("scenes/fig6_sphere.toml")).unwrap();
    common::scene_from_str(&text.replace("resolution = [720, 480]", "resolution = [180, 120]"))
}

fn error(data: &SceneData, reference: &[DVec3]) -> Difference {
    difference(&to_f64(&render_cpu(data)), reference, data.exposure)
}

fn assert_finite(img: &[Vec4], what: &str) {
    let bad = img.iter().filter(|p| !p.truncate().is_finite() || p.truncate().min_element() < 0.0).count();
    assert_eq!(bad, 0, "{what}: {bad} pixels are NaN, infinite or negative");
}

#[test]
fn fig6_default_settings_within_half_a_percent_of_reference() {
    let data = fig6_small();
    let (refimg, samples) = reference::render_converged(&data, 2e-4);
    let d = error(&data, &refimg);
    println!("fig6 180x120, 30 planes x 6 sub-planes vs reference ({samples} samples/ray): {d:?}");
    // The issue's target: 0.5 % of the 8-bit range, RMS (the paper: 2.6 %).
    assert!(d.rms_8bit_percent < 0.5, "{d:?}");
}

#[test]
fn error_falls_as_planes_and_subplanes_grow() {
    let data = fig6_small();
    let (refimg, _) = reference::render_converged(&data, 2e-4);
    let by_planes: Vec<f64> = [4, 16, 64]
        .iter()
        .map(|&n| error(&with_shafts(&data, n, 6, ShaftMode::Exact, false), &refimg).rms_relative)
        .collect();
    println!("rms error vs planes 4, 16, 64 (6 sub-planes): {by_planes:?}");
    assert!(by_planes[0] > by_planes[1] && by_planes[1] > by_planes[2], "{by_planes:?}");
    let by_sub: Vec<f64> = [1, 4, 16]
        .iter()
        .map(|&m| error(&with_shafts(&data, 8, m, ShaftMode::Exact, false), &refimg).rms_relative)
        .collect();
    println!("rms error vs sub-planes 1, 4, 16 (8 planes): {by_sub:?}");
    assert!(by_sub[0] > by_sub[1] && by_sub[1] > by_sub[2], "{by_sub:?}");
}

#[test]
fn tables_cost_little_accuracy() {
    let data = fig6_small();
    let exact = to_f64(&render_cpu(&with_shafts(&data, 30, 6, ShaftMode::Exact, true)));
    let tables = to_f64(&render_cpu(&with_shafts(&data, 30, 6, ShaftMode::Tables, true)));
    let d = difference(&tables, &exact, data.exposure);
    println!("tables (256 + 256x256) vs exact: {d:?}");
    // Linear interpolation in 256 nodes of smooth functions: relative error
    // ~(1/256)^2 times their curvature, far below one 8-bit step.
    assert!(d.rms_8bit_percent < 0.05 && d.max_relative < 1e-3, "{d:?}");
}

/// One spotlight, one sphere, a floor, in a medium with albedo 0.8.
fn stress_scene(
    sigma_t: f64,
    light_pos: [f64; 3],
    light_dir: [f64; 3],
    cutoff: f64,
    camera: [f64; 3],
    phase: &str,
) -> String {
    format!(
        r#"
        [camera]
        position = [{}, {}, {}]
        look_at = [0.0, 1.0, 0.0]
        vfov_deg = 60.0
        resolution = [49, 33]
        [medium]
        sigma_s = [{s}, {s}, {s}]
        sigma_t = [{sigma_t}, {sigma_t}, {sigma_t}]
        phase = {phase}
        [shafts]
        planes = 20
        subplanes = 4
        [[spotlight]]
        position = [{}, {}, {}]
        direction = [{}, {}, {}]
        cutoff_deg = {cutoff}
        intensity = [50.0, 50.0, 50.0]
        shadow_map_resolution = 128
        [[object]]
        type = "sphere"
        center = [0.0, 1.0, 0.0]
        radius = 0.4
        [[object]]
        type = "quad"
        center = [0.0, 0.0, 0.0]
        u = [10.0, 0.0, 0.0]
        v = [0.0, 0.0, 10.0]
        "#,
        camera[0],
        camera[1],
        camera[2],
        light_pos[0],
        light_pos[1],
        light_pos[2],
        light_dir[0],
        light_dir[1],
        light_dir[2],
        s = sigma_t * 0.8,
    )
}

const ISO: &str = r#"{ kind = "isotropic" }"#;

/// Renders, checks every pixel is finite and non-negative, and returns the
/// RMS difference against the converged reference relative to its peak.
fn stress(name: &str, toml: &str) -> f64 {
    let data = common::scene_from_str(toml);
    let img = render_cpu(&data);
    assert_finite(&img, name);
    let (refimg, _) = reference::render_converged(&data, 1e-3);
    assert!(refimg.iter().all(|p| p.is_finite()), "{name}: reference not finite");
    // A stress case that lights no pixel would prove nothing.
    if data.common.sigma_t.x < 100.0 {
        assert!(refimg.iter().any(|p| p.max_element() > 0.0), "{name}: nothing is lit");
    }
    let d = difference(&to_f64(&img), &refimg, 1.0);
    println!("{name}: {d:?}");
    d.rms_relative
}

#[test]
fn extinction_from_1e_minus_6_to_1e3() {
    for sigma_t in [1e-6, 1e-2, 1.0, 1e3] {
        let err = stress(
            &format!("sigma_t {sigma_t}"),
            &stress_scene(sigma_t, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [0.0, 1.5, 6.0], ISO),
        );
        // 20 planes x 4 sub-planes on a 48x32 image: the same few-% RMS class
        // as the default settings' measured error; what must not happen is a
        // blow-up at either end.
        assert!(err < 0.03, "sigma_t {sigma_t}: rms {err}");
    }
}

#[test]
fn camera_inside_the_cone_and_at_the_light() {
    let inside =
        stress("camera inside cone", &stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 40.0, [0.0, 2.5, 0.8], ISO));
    assert!(inside < 0.05, "{inside}");
    // The eye at the light: every view ray starts at the apex, where 1/s^2
    // is largest. Finite is the requirement (the radiance is huge).
    let data =
        common::scene_from_str(&stress_scene(0.1, [0.0, 4.0, 0.01], [0.0, -1.0, 0.0], 40.0, [0.0, 4.0, 0.01], ISO));
    assert_finite(&render_cpu(&data), "camera at the light");
}

#[test]
fn view_ray_through_the_light() {
    // The centre pixel's ray (49x33: there is a centre pixel) passes exactly
    // through the light position: a sample can land on the light.
    // LIGHT_RADIUS bounds 1/s^2 there.
    let toml = stress_scene(0.1, [0.0, 1.0, 3.0], [0.0, -1.0, -0.2], 30.0, [0.0, 1.0, 6.0], ISO);
    let data = common::scene_from_str(&toml);
    assert_finite(&render_cpu(&data), "ray through the light");
}

#[test]
fn cone_angles_near_0_and_90_degrees() {
    // Near 0: a 0.05 degree beam is 7 mm wide at the sphere; no uniform ray
    // march resolves it, so the check is that the method, which clips each
    // ray to the cone analytically, still sees it in the centre column (whose
    // rays cross the axis) and stays finite.
    for cutoff in [0.05, 0.5] {
        let data =
            common::scene_from_str(&stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], cutoff, [0.0, 1.5, 6.0], ISO));
        let img = render_cpu(&data);
        assert_finite(&img, &format!("cutoff {cutoff}"));
        let centre_column_lit = (0..33).any(|y| img[y * 49 + 24].x > 0.0);
        assert!(centre_column_lit, "cutoff {cutoff}: the beam is lost");
    }
    for cutoff in [60.0, 85.0, 89.9] {
        let err = stress(
            &format!("cutoff {cutoff}"),
            &stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], cutoff, [0.0, 1.5, 6.0], ISO),
        );
        // Near 90 degrees the 128^2 shadow map spreads over a huge footprint
        // (tan 89.9 = 573) and the floor is lit to the horizon; the bound is
        // loose for that, and the shafts stay finite.
        assert!(err < 0.1, "cutoff {cutoff}: rms {err}");
    }
}

#[test]
fn light_parallel_to_the_sample_planes() {
    // The beam runs across the screen, inside one plane's depth.
    let err = stress(
        "beam parallel to planes",
        &stress_scene(0.1, [-4.0, 1.5, 0.0], [1.0, 0.0, 0.0], 15.0, [0.0, 1.5, 6.0], ISO),
    );
    assert!(err < 0.05, "{err}");
}

#[test]
fn henyey_greenstein_at_plus_minus_0_999() {
    for g in [-0.999, 0.999] {
        let phase = format!(r#"{{ kind = "henyey-greenstein", g = {g} }}"#);
        let data = common::scene_from_str(&stress_scene(
            0.1,
            [0.0, 4.0, 0.0],
            [0.0, -1.0, 0.0],
            30.0,
            [0.0, 1.5, 6.0],
            &phase,
        ));
        assert_finite(&render_cpu(&data), &format!("g {g}"));
    }
}

#[test]
fn scene_1e5_metres_away() {
    // The whole scene moved 1e5 m along x, camera included: f32 positions
    // keep ~8 mm there, which the 0.4 m sphere and the 10 m floor survive.
    let far = 1.0e5;
    let toml = stress_scene(0.1, [far, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [far, 1.5, 6.0], ISO)
        .replace("look_at = [0.0, 1.0, 0.0]", &format!("look_at = [{far}, 1.0, 0.0]"))
        .replace("center = [0.0, 1.0, 0.0]", &format!("center = [{far}, 1.0, 0.0]"))
        .replace("center = [0.0, 0.0, 0.0]", &format!("center = [{far}, 0.0, 0.0]"));
    let err = stress("1e5 m away", &toml);
    assert!(err < 0.05, "{err}");
}

#[test]
fn one_plane_and_ten_thousand_planes() {
    let data =
        common::scene_from_str(&stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [0.0, 1.5, 6.0], ISO));
    let (refimg, _) = reference::render_converged(&data, 1e-3);
    let one = render_cpu(&with_shafts(&data, 1, 1, ShaftMode::Exact, true));
    assert_finite(&one, "1 plane");
    let many = render_cpu(&with_shafts(&data, 10_000, 1, ShaftMode::Exact, true));
    assert_finite(&many, "10000 planes");
    let d_one = difference(&to_f64(&one), &refimg, 1.0);
    let d_many = difference(&to_f64(&many), &refimg, 1.0);
    println!("1 plane: {d_one:?}\n10000 planes: {d_many:?}");
    // 10000 planes is a fine midpoint rule: it must sit at the reference's
    // own noise level, and far below a single plane.
    assert!(d_many.rms_relative < 0.01 && d_many.rms_relative < d_one.rms_relative, "{d_many:?} vs {d_one:?}");
}

#[test]
fn one_by_one_image() {
    let toml = stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [0.0, 1.5, 6.0], ISO)
        .replace("resolution = [49, 33]", "resolution = [1, 1]");
    let data = common::scene_from_str(&toml);
    let img = render_cpu(&data);
    assert_eq!(img.len(), 1);
    assert_finite(&img, "1x1");
}

#[test]
fn clear_air_skips_the_shafts_pass() {
    let toml = stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [0.0, 1.5, 6.0], ISO);
    let data = common::scene_from_str(&toml).reconfigure(move |f| f.medium.sigma_s = [0.0; 3]).unwrap();
    let plan = render::plan(&data);
    let shafts = plan.iter().find(|p| p.name == "shafts").unwrap();
    assert!(!shafts.ran && shafts.reason.contains("does not scatter"), "{shafts:?}");
    // Surfaces cast shadow rays, so nothing needs the shadow maps either;
    // with shadow-mapped surfaces they run again.
    let maps = plan.iter().find(|p| p.name == "shadow_maps").unwrap();
    assert!(!maps.ran, "{maps:?}");
    let data = data.reconfigure(|f| f.surface.shadows = SurfaceShadows::ShadowMap).unwrap();
    assert!(render::plan(&data).iter().any(|p| p.name == "shadow_maps" && p.ran));
}

#[test]
fn a_light_behind_the_camera_is_culled() {
    // The spotlight sits behind the camera and points away from the view.
    let toml = stress_scene(0.1, [0.0, 2.0, 10.0], [0.0, 0.0, 1.0], 20.0, [0.0, 1.5, 6.0], ISO);
    let data = common::scene_from_str(&toml);
    assert_eq!(data.lights[0].in_view, 0);
    let plan = render::plan(&data);
    assert!(!plan.iter().find(|p| p.name == "shafts").unwrap().ran);
    // And one in front is kept.
    let data =
        common::scene_from_str(&stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [0.0, 1.5, 6.0], ISO));
    assert_eq!(data.lights[0].in_view, 1);
}

#[test]
fn eight_bit_mode_reproduces_the_papers_plane_count_trade_off() {
    // The 2002 paper's Fig. 4: with 8-bit tables and 8-bit blending, error
    // falls with more planes until rounding each plane's contribution
    // dominates, then rises again (the paper chose 30 planes).
    let data = fig6_small();
    let (refimg, _) = reference::render_converged(&data, 2e-4);
    let err = |n: u32| {
        let d = data
            .reconfigure(move |f| {
                let s = &mut f.shafts;
                s.planes = n;
                s.subplanes = 1;
                s.mode = ShaftMode::Tables;
                s.jitter = false;
                s.quantize_8bit = true;
            })
            .unwrap();
        error(&d, &refimg).rms_8bit_percent
    };
    let (few, paper, many) = (err(5), err(30), err(120));
    println!("8-bit mode, rms % of 8-bit range: 5 planes {few:.3}, 30 planes {paper:.3}, 120 planes {many:.3}");
    assert!(paper < few && paper < many, "{few} {paper} {many}");
}

#[test]
fn an_8192_by_8192_image() {
    // 67 M pixels: 1 GiB of f32 RGBA for the image on the CPU backend. Two
    // planes of one sub-plane keep it to seconds; the point is that nothing
    // overflows (pixel indices, sample counts) and every pixel is finite. The
    // GPU path's bands are tested in equivalence.rs.
    let text = std::fs::read_to_string(common::root().join("scenes/fig6_sphere.toml")).unwrap();
    let data = common::scene_from_str(&text.replace("resolution = [720, 480]", "resolution = [8192, 8192]"));
    let data = with_shafts(&data, 2, 1, ShaftMode::Exact, true);
    let (img, stats) = render::render(&data, &Backend::Cpu, false).unwrap();
    assert_eq!(img.len(), 8192 * 8192);
    assert!(stats.counter("shaft_samples") > 0);
    assert_finite(&img, "8192x8192");
    assert!(img.iter().any(|p| p.x > 0.0), "nothing is lit");
}

/// A camera 6 m from a spotlight, looking across its apex, in a medium with
/// a forward-peaked phase function: the pixels within 12 px of the apex's
/// image, method against reference (the same pixel centres), mean and worst
/// relative error of the in-scattered-plus-surface radiance.
fn apex_error(phase: &str) -> (f64, f64) {
    let toml = format!(
        r#"
        [camera]
        position = [6.0, 3.0, 0.5]
        look_at = [0.0, 3.0, 0.0]
        vfov_deg = 40.0
        resolution = [96, 64]
        [medium]
        sigma_s = [0.05, 0.05, 0.05]
        sigma_t = [0.06, 0.06, 0.06]
        phase = {phase}
        [[spotlight]]
        position = [0.0, 3.0, 0.0]
        direction = [0.0, -1.0, 0.3]
        cutoff_deg = 25.0
        intensity = [40.0, 30.0, 20.0]
        [[object]]
        type = "quad"
        center = [0.0, 0.0, 0.0]
        u = [12.0, 0.0, 0.0]
        v = [0.0, 0.0, 12.0]
        "#
    );
    let data = common::scene_from_str(&toml);
    let img = render_cpu(&data);
    // The apex projects near the image centre (the camera looks at it).
    let (cx, cy, r) = (48i32, 32i32, 12i32);
    let pixels: Vec<u32> = (0..data.pixel_count())
        .filter(|&i| {
            let (x, y) = ((i % 96) as i32, (i / 96) as i32);
            (x - cx).pow(2) + (y - cy).pow(2) <= r * r
        })
        .collect();
    let (refimg, samples) = reference::render_converged_at(&data, &pixels, 1e-4);
    let mut rel: Vec<f64> = Vec::new();
    for (&i, r) in pixels.iter().zip(&refimg) {
        let m = img[i as usize].truncate().as_dvec3();
        if r.max_element() > 0.0 {
            rel.push(((m - *r).abs() / r.max(DVec3::splat(1e-12))).max_element());
        }
    }
    let mean = rel.iter().sum::<f64>() / rel.len() as f64;
    let worst = rel.iter().cloned().fold(0.0, f64::max);
    println!(
        "{phase}: {} lit pixels near the apex, reference {samples} samples: mean {mean:.4}, worst {worst:.4}",
        rel.len()
    );
    (mean, worst)
}

#[test]
fn looking_across_a_lights_apex_stays_within_one_percent() {
    // Sampling the phase at each interval's middle in t made these pixels
    // 15-17 % too bright; averaging it over the angle seen from the light
    // (where the 1/s^2 weight is uniform) must keep them within 1 % on
    // average. The worst pixel may also carry the cone edge's and the
    // dither's error (a pixel the cone's edge crosses), so it gets 5 %.
    for phase in [r#"{ kind = "henyey-greenstein", g = 0.9 }"#, r#"{ kind = "dobashi2002" }"#] {
        let (mean, worst) = apex_error(phase);
        assert!(mean < 0.01 && worst < 0.05, "{phase}: mean {mean}, worst {worst}");
    }
}

#[test]
fn shadow_maps_default_to_what_they_serve() {
    // Two spots, one with its own resolution, and the maps lie one after the
    // other. The default one's resolution follows the footprint rule while
    // only the shafts read it (`shadow_maps::shafts_resolution`), and is 512
    // once surfaces are shadowed by the maps too.
    use slicelight::common::shadow_maps::{footprint_rays, shafts_resolution};
    use slicelight::scene::{SHAFTS_MIN_SHADOW_MAP_RESOLUTION as MIN, SURFACE_SHADOW_MAP_RESOLUTION as MAX};
    let spot = |res: u32| {
        format!("[[spotlight]]\nposition = [1.0, 4.0, 0.0]\ndirection = [0.0, -1.0, 0.0]\ncutoff_deg = 20.0\nintensity = [5.0, 5.0, 5.0]\nshadow_map_resolution = {res}\n")
    };
    let toml = stress_scene(0.1, [0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 30.0, [0.0, 1.5, 6.0], ISO)
        .replace("shadow_map_resolution = 128", "")
        + &spot(100);
    let data = common::scene_from_str(&toml);
    let layout = |d: &slicelight::scene::SceneData| {
        let maps: Vec<_> = d.lights.iter().map(|l| (l.shadow_resolution, l.shadow_offset)).collect();
        (maps, d.common.shadow_texel_count)
    };
    // 49x33 pixels: a pixel spans 8 cm at the sphere, far more than a
    // 128-texel map's texel there; the least resolution is the default.
    assert_eq!(layout(&data), (vec![(MIN, 0), (100, MIN * MIN)], MIN * MIN + 100 * 100));
    let mapped = data.reconfigure(|f| f.surface.shadows = SurfaceShadows::ShadowMap).unwrap();
    assert_eq!(layout(&mapped), (vec![(MAX, 0), (100, MAX * MAX)], MAX * MAX + 100 * 100));
    let rays = mapped.reconfigure(|f| f.surface.shadows = SurfaceShadows::Rays).unwrap();
    assert_eq!(layout(&rays).1, MIN * MIN + 100 * 100);

    // The rule itself: texels no wider than a pixel where the cone is seen.
    // Twice the image height halves the pixels' footprint and doubles the
    // resolution (to the next multiple of 32), until it reaches the cap; a
    // camera inside the cone, whose pixels shrink to nothing at the eye,
    // gets the cap; a view that misses the cone gets the least.
    let fig6 = slicelight::scene::load(&common::root().join("scenes/fig6_sphere.toml")).unwrap();
    let light = fig6.lights[0];
    let at_height = |h: u32, eye: glam::Vec3, look: glam::Vec3| {
        let d = fig6
            .reconfigure(move |f| {
                f.camera.resolution = [h * 3 / 2, h];
                f.camera.position = eye.to_array();
                f.camera.look_at = look.to_array();
                f.camera.vfov_deg = Some(45.0);
            })
            .unwrap();
        shafts_resolution(&d.common, &light, &footprint_rays(&d.common, &d.geometry(), 100.0), 32, 4096)
    };
    let (eye, look) = (glam::Vec3::new(0.0, 1.8, 8.0), glam::Vec3::new(0.0, 1.8, 0.0));
    let (r1, r2) = (at_height(120, eye, look), at_height(240, eye, look));
    println!("fig6 view: {r1} texels at 120 rows, {r2} at 240");
    assert!(r1 > 32 && r2 < 4096, "{r1} {r2}");
    assert!(r2.abs_diff(2 * r1) <= 64, "{r1} -> {r2}");
    // Eye in the cone, looking down its axis.
    let inside = at_height(240, glam::Vec3::new(0.0, 5.0, 0.0), glam::Vec3::new(0.0, 0.0, 0.01));
    assert_eq!(inside, 4096);
    // Looking away from the cone: nothing of it is seen.
    let away = at_height(240, glam::Vec3::new(6.0, 1.8, 8.0), glam::Vec3::new(12.0, 1.8, 16.0));
    assert_eq!(away, 32);

    // Too many texels in all (65 maps of 8192^2 pass 2^32) is an error
    // naming the field, not a wrap-around.
    let mut huge = toml.clone();
    for _ in 0..65 {
        huge += &spot(8192);
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("huge.toml"), huge).unwrap();
    let err = slicelight::scene::load(&dir.path().join("huge.toml")).map(|_| ()).unwrap_err();
    assert!(format!("{err:#}").contains("shadow_map_resolution"), "{err:#}");
}
