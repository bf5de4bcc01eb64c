//! Volumes (`[[volume]]`): the slice renderer against the f64 reference,
//! the stress cases at the edges of the parameters, and the errors bad
//! input gets.

mod common;

use slicelight::metrics::{difference, to_f64};
use slicelight::render::{render, Backend};
use slicelight::scene::SceneData;

/// A shipped scene at a smaller resolution, through the validating path.
fn shipped(name: &str, width: u32, height: u32) -> SceneData {
    let data = slicelight::scene::load(&common::root().join(format!("scenes/{name}.toml"))).unwrap();
    data.reconfigure(move |f| f.camera.resolution = [width, height]).unwrap()
}

fn cpu_image(data: &SceneData) -> Vec<glam::Vec4> {
    render(data, &Backend::Cpu, false).unwrap().0
}

/// A shipped scene at `width x height` with `scattering = "single"`, its
/// CPU image, that image's difference from the f64 reference at
/// `tolerance` (printed), and the reference.
fn single_against_reference(
    name: &str,
    width: u32,
    height: u32,
    tolerance: f64,
) -> (SceneData, Vec<glam::DVec3>, slicelight::metrics::Difference, Vec<glam::DVec3>) {
    let data = shipped(name, width, height)
        .reconfigure(move |f| f.volumes.scattering = slicelight::volumes::Scattering::Single)
        .unwrap();
    assert!(data.volumes.enabled && data.volumes.params.octaves == 1);
    let image = to_f64(&cpu_image(&data));
    let (reference, samples) = slicelight::reference::render_converged(&data, tolerance);
    let d = difference(&image, &reference, data.exposure);
    println!(
        "{name} {width}x{height}: {:.3} % RMS, {:.3} % max of the 8-bit range ({samples} reference samples per ray)",
        d.rms_8bit_percent, d.max_8bit_percent
    );
    (data, image, d, reference)
}

/// Pixels of `image` that differ (by more than 1e-3 relative) from the
/// same scene rendered without its volumes: how much of the picture they cover.
fn covered_pixels(data: &SceneData, image: &[glam::DVec3]) -> usize {
    let clear = to_f64(&cpu_image(&data.reconfigure(move |f| f.volume.clear()).unwrap()));
    image.iter().zip(&clear).filter(|(a, b)| (**a - **b).length() > 1e-3 * b.length()).count()
}

/// Every pixel finite and non-negative, and the volumes' transmittance
/// layer (where it ran) within [0, 1].
fn assert_sane(what: &str, data: &SceneData) {
    let r = slicelight::render::render_layers(data, &Backend::Cpu, false).unwrap();
    for (i, p) in r.image.iter().enumerate() {
        assert!(p.is_finite() && p.min_element() >= 0.0, "{what}: pixel {i} is {p}");
    }
    for (_, layer) in r.layers.iter().filter(|(n, _)| *n == "volumes" || *n == "volume_splats") {
        for p in layer.as_slice::<glam::Vec4>() {
            assert!(p.truncate().is_finite() && p.truncate().min_element() >= 0.0, "{what}: volume radiance {p}");
        }
    }
}

/// The cumulus at 64x48 pixel centres with `scattering = "single"` against
/// the f64 reference (analytic field, nested marching toward the sun). Measured: 0.19 % RMS of the
/// 8-bit range here (0.10 % at 80x60 and at 40x30, whose pixels fall
/// elsewhere on the cloud's edge); the bound, 0.5 %, is two and a half times
/// that and half the issue's 1 %: what a change to the planes, the density
/// grid or the transmittance volume's defaults must keep.
///
/// Splatting (`cloud_cumulus_splat`'s method) on the same pixels against
/// the same reference: measured 4.14 % RMS, 28.6 % at worst, energy 0.972.
/// Lit at each ball's centre, as the paper does (deep in a ball of optical
/// depth ~3.6, though the eye sees mostly its sunlit front), it was
/// 8.02 %, 40 % and 0.929; each billboard's texture now holds the light
/// where the eye sees the ball. What is left: overlapping balls taken as
/// layers in the order of their centres. The bounds, 6 % RMS and energy
/// within 0.94..1.02, hold the gain, so a change that brings back the
/// centre's light (or a broken step 1, which leaves it black) fails.
#[test]
fn cumulus_matches_the_reference() {
    let (data, image, d, reference) = single_against_reference("cloud_cumulus", 64, 48, 2e-4);
    assert!(d.rms_8bit_percent < 0.5, "{d:?}");
    // The cloud is in the picture: it hides part of the sky.
    let changed = covered_pixels(&data, &image);
    assert!(changed > image.len() / 20, "the cloud covers {changed} of {} pixels", image.len());
    let splat = splatted(&data);
    let s = difference(&to_f64(&cpu_image(&splat)), &reference, data.exposure);
    println!(
        "cloud_cumulus 64x48 splatted: {:.3} % RMS, {:.3} % max of the 8-bit range, energy {:.4}",
        s.rms_8bit_percent, s.max_8bit_percent, s.energy_ratio
    );
    assert!(s.rms_8bit_percent < 6.0 && (0.94..1.02).contains(&s.energy_ratio), "{s:?}");
}

/// The scene with every volume drawn by splatting.
fn splatted(data: &SceneData) -> SceneData {
    let s = data
        .reconfigure(move |f| f.volume.iter_mut().for_each(|v| v.method = slicelight::volumes::Method::Splatting))
        .unwrap();
    assert_eq!(s.volumes.params.method, slicelight::shaders::volumes::METHOD_SPLATTING);
    s
}

/// Every pass the scene runs, on the CPU, into one frame (its last sample's
/// per-pixel layers and every table).
fn cpu_frame(data: &SceneData) -> slicelight::passes::Frame {
    use slicelight::passes::{Frame, PASSES};
    let pb = indicatif::ProgressBar::hidden();
    let mut frame = Frame::default();
    for r in PASSES.iter().flat_map(|p| p.reads().iter().chain(p.writes())) {
        if let Some(blank) = r.blank(data.pixel_count() as usize) {
            frame.insert(r, blank);
        }
    }
    for &pass in PASSES.iter() {
        if pass.plan(data).runs {
            pass.run_cpu(data, &data.common, &mut frame, &pb);
        }
    }
    frame
}

/// Splatting's view transmittance is exact: the billboards' chords are the
/// field's integral in closed form, so the product of their attenuations
/// is `exp(-tau)` of the whole ray through overlapping metaballs, clipped
/// by the box and the floor. Against 4096 jittered strata in f64 on every
/// pixel of the puff (optical depths up to ~1.5): within 2e-4 (f32 exps
/// and sums; measured in the print). The slices' transmittance, from the
/// density grid by planes, is printed beside it.
#[test]
fn splatted_transmittance_is_exact() {
    use slicelight::shaders::camera::camera_ray;
    let data = splatted(&puff(BALLS, "", ""));
    let frame = cpu_frame(&data);
    let splat = frame.get::<glam::Vec4>(&slicelight::volumes::splat::SPLAT_TRANSMITTANCE);
    let slices = cpu_frame(&puff(BALLS, "", ""));
    let slices = slices.get::<glam::Vec4>(&slicelight::volumes::VOLUME_TRANSMITTANCE);
    let gbuffer = frame.get::<slicelight::shaders::types::GBufferTexel>(&slicelight::passes::GBUFFER);
    let (mut worst, mut worst_slices, mut seen) = (0.0f64, 0.0f64, 0);
    for y in 0..data.height() {
        for x in 0..data.width() {
            let i = (y * data.width() + x) as usize;
            let (o, d) = camera_ray(&data.common, x, y);
            let distance = gbuffer[i].normal_distance.w as f64;
            let exact =
                slicelight::volumes::reference::transmittance_strata(&data, o.as_dvec3(), d.as_dvec3(), distance, 4096);
            if exact.x < 0.999 {
                seen += 1;
            }
            worst = worst.max((splat[i].truncate().as_dvec3() - exact).abs().max_element());
            worst_slices = worst_slices.max((slices[i].truncate().as_dvec3() - exact).abs().max_element());
        }
    }
    println!(
        "puff transmittance on {seen} pixels: splatting within {worst:.2e} of exp(-tau), slices {worst_slices:.2e}"
    );
    assert!(seen > 100, "the puff covers {seen} pixels");
    assert!(worst < 2e-4, "splatting's transmittance is {worst} from exp(-tau)");
}

/// On one thin metaball (optical depth 0.016 through its centre) the light
/// is nearly the same all over it, so splatting is nearly exact: its
/// radiance against the f64 reference's single scattering over the pixels
/// it covers, under the sun (through its bins) and under the sun and a
/// spotlight (whose balls are all walked). Measured: sun 0.9998 of the
/// summed radiance, 0.16 % at worst (lit at the centre, before the
/// billboards' textures: 0.9965 and 0.83 %, the sun's light varying by
/// ±0.8 % over the ball); with the spot 1.003 and 3.4 % at worst (before:
/// 0.992 and 8.0 %, the spot's 1/r^2, 0.57 to 2.2 times the centre's over
/// the ball 2.5 m from it, read at the centre; now the light is sampled at
/// three points along the key light's axis, the sun's, and the spot's
/// share varies between them). Bounds: 2 % and 3 %; 2 % and 12 %.
#[test]
fn one_thin_metaball_splats_as_the_reference() {
    let spot = "[[spotlight]]\nposition = [0.0, 3.0, 1.5]\ndirection = [0.0, -0.8, -0.6]\ncutoff_deg = 40.0\nbeam_deg = 35.0\nintensity = [3.0, 3.0, 3.0]";
    for (lights, worst_bound) in [("", 0.03), (spot, 0.12)] {
        thin_metaball_against_reference(lights, worst_bound);
    }
}

fn thin_metaball_against_reference(lights: &str, worst_bound: f64) {
    use slicelight::shaders::camera::camera_ray;
    let data = splatted(
        &puff("[0.0, 1.0, 0.0, 0.8, 1.0]", "", &format!("{lights}\n[volumes]\nscattering = \"single\""))
            .reconfigure(move |f| {
                f.volume[0].sigma_t = [0.02; 3];
                f.volume[0].sigma_s = [0.018; 3];
            })
            .unwrap(),
    );
    let frame = cpu_frame(&data);
    let splat = frame.get::<glam::Vec4>(&slicelight::volumes::splat::SPLAT_RADIANCE);
    let gbuffer = frame.get::<slicelight::shaders::types::GBufferTexel>(&slicelight::passes::GBUFFER);
    let peak = splat.iter().map(|p| p.x).fold(0.0f32, f32::max) as f64;
    assert!(peak > 0.0, "the ball scatters no light");
    let (mut sum, mut sum_ref, mut worst) = (0.0f64, 0.0f64, 0.0f64);
    for y in 0..data.height() {
        for x in 0..data.width() {
            let i = (y * data.width() + x) as usize;
            let (o, d) = camera_ray(&data.common, x, y);
            let t = gbuffer[i].normal_distance.w as f64;
            let (exact, _) =
                slicelight::volumes::reference::volume_ray(&data, o.as_dvec3(), d.as_dvec3(), t, 512, i as u64);
            let got = splat[i].x as f64;
            sum += got;
            sum_ref += exact.x;
            if exact.x > 0.1 * peak {
                worst = worst.max((got - exact.x).abs() / exact.x);
            }
        }
    }
    println!(
        "one thin metaball, {} light(s): splatted radiance {:.4} of the reference's, worst pixel {:.2} %",
        data.lights.len(),
        sum / sum_ref,
        100.0 * worst
    );
    assert!((sum / sum_ref - 1.0).abs() < 0.02, "{sum} against {sum_ref}");
    assert!(worst < worst_bound, "worst pixel {worst}");
}

/// One thick metaball (optical depth 3.2 through its centre, as the
/// cumulus' balls' ~3.6) under the sun, single scattering: the sun's light
/// falls by `e^-1.6` from the ball's sunlit face to its centre, so the
/// paper's one colour per ball (the light at the centre) is far too dark
/// where the eye sees the ball. Splatting takes the light where the eye
/// sees it instead (the chord's emission quartiles, read between three
/// samples along the sun's axis, `seen_color`, in the billboard's 4x4
/// texture). Against the f64 reference over the pixels brighter than a
/// tenth of the peak: measured (docs/volumes.md) RMS 6.3 % of the
/// reference (per pixel) and energy 0.984; lit at the centre (`(1 -
/// e^-tau) c_centre`, what splatting drew before) 65 % and 0.34. The
/// bounds: 10 % and within 3 %; the centre-lit image at least five times
/// further.
#[test]
fn a_thick_metaball_is_lit_where_the_eye_sees_it() {
    use slicelight::shaders::camera::camera_ray;
    use slicelight::shaders::volumes::splat::{chord, SplatBall};
    let data = splatted(
        &puff("[0.0, 1.0, 0.0, 0.8, 1.0]", "", "[volumes]\nscattering = \"single\"")
            .reconfigure(move |f| {
                f.volume[0].sigma_t = [4.0; 3];
                f.volume[0].sigma_s = [3.6; 3];
            })
            .unwrap(),
    );
    let frame = cpu_frame(&data);
    let splat = frame.get::<glam::Vec4>(&slicelight::volumes::splat::SPLAT_RADIANCE);
    let billboard = frame.get::<SplatBall>(&slicelight::volumes::splat::SPLATS)[0];
    let gbuffer = frame.get::<slicelight::shaders::types::GBufferTexel>(&slicelight::passes::GBUFFER);
    let ball = data.volumes.balls[0];
    let mut rows = Vec::new();
    for y in 0..data.height() {
        for x in 0..data.width() {
            let i = (y * data.width() + x) as usize;
            let (o, d) = camera_ray(&data.common, x, y);
            let t = gbuffer[i].normal_distance.w;
            let (exact, _) =
                slicelight::volumes::reference::volume_ray(&data, o.as_dvec3(), d.as_dvec3(), t as f64, 512, i as u64);
            let centre_lit = (1.0 - (-4.0 * chord(&ball, o, d, 0.0, t)).exp()) * billboard.color.x;
            rows.push((exact.x, splat[i].x as f64, centre_lit as f64));
        }
    }
    let peak = rows.iter().map(|r| r.0).fold(0.0, f64::max);
    assert!(peak > 0.0, "the ball scatters no light");
    let lit: Vec<_> = rows.iter().filter(|r| r.0 > 0.1 * peak).collect();
    let rms = |pick: fn(&&(f64, f64, f64)) -> f64| {
        (lit.iter().map(|r| ((pick(r) - r.0) / r.0).powi(2)).sum::<f64>() / lit.len() as f64).sqrt()
    };
    let energy =
        |pick: fn(&(f64, f64, f64)) -> f64| rows.iter().map(pick).sum::<f64>() / rows.iter().map(|r| r.0).sum::<f64>();
    let (seen, centre) = (rms(|r| r.1), rms(|r| r.2));
    let (e_seen, e_centre) = (energy(|r| r.1), energy(|r| r.2));
    println!(
        "one thick metaball over {} pixels: RMS {:.2} % of the reference, energy {e_seen:.4}; lit at its centre {:.2} %, {e_centre:.4}",
        lit.len(),
        100.0 * seen,
        100.0 * centre
    );
    assert!(seen < 0.10 && (e_seen - 1.0).abs() < 0.03, "RMS {seen}, energy {e_seen}");
    assert!(centre > 5.0 * seen, "lit at the centre: RMS {centre}");
}

/// The CPU backend ranks the billboards by sorting their keys, where the
/// kernel counts the nearer balls (`splat_rank`, `n^2`): the same order,
/// ties by index, on balls with equal distances from the eye.
#[test]
fn the_sorted_order_is_the_counted_one() {
    use slicelight::shaders::volumes::splat::splat_rank;
    // Eight balls, three pairs at equal distances (mirror images across
    // the view axis), one at the eye's distance of another's.
    let balls = "[0.5, 1.0, 0.0, 0.2, 1.0], [-0.5, 1.0, 0.0, 0.2, 1.0], [0.0, 1.0, -0.5, 0.2, 1.0], \
                 [0.3, 1.2, 0.4, 0.2, 1.0], [-0.3, 1.2, 0.4, 0.2, 1.0], [0.0, 1.0, 0.5, 0.2, 1.0], \
                 [0.2, 0.8, -0.2, 0.2, 1.0], [-0.2, 0.8, -0.2, 0.2, 1.0]";
    let data = splatted(&puff(balls, "", ""));
    let frame = cpu_frame(&data);
    let order = frame.get::<u32>(&slicelight::volumes::splat::SPLAT_ORDER);
    let v = &data.volumes;
    let counted: Vec<u32> =
        (0..v.params.ball_count).map(|j| splat_rank(j, &data.common, &v.params, &v.balls)).collect();
    let mut from_counts = vec![u32::MAX; counted.len()];
    for (j, &r) in counted.iter().enumerate() {
        from_counts[r as usize] = j as u32;
    }
    assert_eq!(order, &from_counts[..], "ranks counted {counted:?}");
}

/// The default, multiple scattering by delta-Eddington columns spread
/// over rings (`diffuse_node`), against the Monte Carlo reference (all
/// orders) on the cumulus at 24x18 pixel centres, beside the columns
/// without rings (`column_spread = 0`, the lateral leakage by
/// `column_width`), the octaves and single scattering on the same pixels.
/// Measured (docs/volumes.md): rings energy 0.998, 3.63 % RMS (8-bit);
/// no rings 0.987, 4.48 %; octaves 0.970, 5.70 %; single scattering 0.655,
/// 19.3 %. The reference stops doubling its paths at a change of 6e-3 (14
/// s here): at 3e-3 (48 s) the figures without rings were 0.990, 4.46 %,
/// so its noise moves them by a few hundredths of a percent. The issue
/// asks 5 % energy and 3 % RMS: the rings meet the first, not the second.
/// The bounds hold most of what the rings gained (RMS below 4 %, energy
/// within 3 %, at least half a point closer than without rings) and keep
/// them at least four times as close as single scattering.
#[test]
fn multiple_scattering_against_monte_carlo() {
    use slicelight::volumes::Scattering;
    let data = shipped("cloud_cumulus", 24, 18);
    assert!(data.volumes.params.columns == 1, "multiple scattering by columns is the default");
    let (reference, _) = slicelight::reference::render_converged(&data, 6e-3);
    let against = |d: &SceneData| difference(&to_f64(&cpu_image(d)), &reference, data.exposure);
    let columns = against(&data);
    let unspread = against(&data.reconfigure(move |f| f.volumes.column_spread = Some(0.0)).unwrap());
    let octaves = against(&data.reconfigure(move |f| f.volumes.scattering = Scattering::Octaves).unwrap());
    let single = against(&data.reconfigure(move |f| f.volumes.scattering = Scattering::Single).unwrap());
    println!(
        "cumulus 24x18 against Monte Carlo: columns {:.3} energy, {:.2} % RMS; without rings {:.3}, {:.2} %; octaves {:.3}, {:.2} %; single {:.3}, {:.2} %",
        columns.energy_ratio,
        columns.rms_8bit_percent,
        unspread.energy_ratio,
        unspread.rms_8bit_percent,
        octaves.energy_ratio,
        octaves.rms_8bit_percent,
        single.energy_ratio,
        single.rms_8bit_percent
    );
    assert!(single.energy_ratio < 0.95, "single scattering misses the higher orders: {single:?}");
    assert!((columns.energy_ratio - 1.0).abs() < 0.03, "{columns:?}");
    assert!(columns.rms_8bit_percent < 4.0, "{columns:?}");
    assert!(columns.rms_8bit_percent < unspread.rms_8bit_percent - 0.5, "{columns:?} against {unspread:?}");
    assert!((unspread.energy_ratio - 1.0).abs() < 0.05 && unspread.rms_8bit_percent < 5.0, "{unspread:?}");
    assert!(columns.rms_8bit_percent < 0.25 * single.rms_8bit_percent, "{columns:?} against {single:?}");
}

/// The Monte Carlo walk counting order 1 only agrees with the quadrature
/// (which shares none of its sampling: delta tracking, ratio tracking,
/// majorants) within four standard errors, on rays through the puff: a
/// check of the machinery that gives the higher orders.
#[test]
fn walk_order_one_matches_the_quadrature() {
    use slicelight::volumes::montecarlo::{walk, Majorants};
    let data = puff(BALLS, "", "");
    let m = Majorants::new(&data);
    let o = glam::DVec3::new(0.0, 1.0, 6.0);
    for target in [[0.0, 1.0, 0.0], [0.4, 1.3, 0.0], [-0.5, 0.8, 0.3]] {
        let d = (glam::DVec3::from(target) - o).normalize();
        let (quadrature, _) = slicelight::volumes::reference::volume_ray(&data, o, d, f64::INFINITY, 4096, 1);
        let n = 20_000;
        let values: Vec<f64> = (0..n).map(|k| walk(&data, &m, o, d, f64::INFINITY, (1, 1), k).x).collect();
        let mean = values.iter().sum::<f64>() / n as f64;
        let sd = (values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1) as f64).sqrt();
        let error = sd / (n as f64).sqrt();
        println!("toward {target:?}: walk {mean:.5} +- {error:.5}, quadrature {:.5}", quadrature.x);
        assert!(quadrature.x > 0.0);
        assert!((mean - quadrature.x).abs() < 4.0 * error + 1e-3 * quadrature.x, "{mean} against {}", quadrature.x);
    }
}

/// A small volume in front of a lit quad, seen by a camera; `extra` goes
/// into the `[[volume]]` table, `balls` is its metaball list, `sky` any
/// extra tables.
fn puff(balls: &str, volume: &str, extra: &str) -> SceneData {
    common::scene_from_str(&format!(
        r#"
        [camera]
        position = [0.0, 1.0, 6.0]
        look_at = [0.0, 1.0, 0.0]
        vfov_deg = 40.0
        resolution = [48, 32]
        [[directional_light]]
        direction = [0.3, -1.0, -0.4]
        irradiance = [2.0, 2.0, 2.0]
        [[object]]
        type = "quad"
        center = [0.0, 0.0, 0.0]
        u = [6.0, 0.0, 0.0]
        v = [0.0, 0.0, 6.0]
        [[volume]]
        min = [-1.5, 0.0, -1.5]
        max = [1.5, 2.5, 1.5]
        sigma_s = [0.9, 0.9, 0.9]
        sigma_t = [1.0, 1.0, 1.0]
        metaballs = [{balls}]
        {volume}
        {extra}
        "#
    ))
}

const BALLS: &str = "[0.0, 1.0, 0.0, 0.8, 1.0], [0.5, 1.4, 0.2, 0.6, 0.8]";

/// Density 0, optical depths from 0 to 10^4, radii of 1 mm and 10 km (in a
/// box to match), one metaball and 10^4 overlapping ones, a camera inside
/// the cloud, an empty volume, a box cutting through the floor: no NaN or
/// Inf, nothing negative; by slices and by splatting.
#[test]
fn stress_cases_stay_finite() {
    sane_cases(&[
        ("density 0", puff("[0.0, 1.0, 0.0, 0.8, 0.0]", "", "")),
        (
            "optical depth 1e4",
            puff(BALLS, "", "")
                .reconfigure(move |f| {
                    f.volume[0].sigma_t = [6000.0; 3];
                    f.volume[0].sigma_s = [5000.0; 3];
                })
                .unwrap(),
        ),
        ("no metaballs", puff("", "", "")),
        ("radius 1 mm", puff("[0.0, 1.0, 0.0, 0.001, 1.0]", "", "")),
        ("box through the floor", puff(BALLS, "", "").reconfigure(move |f| f.volume[0].min[1] = -1.0).unwrap()),
        ("camera inside", puff(BALLS, "", "").reconfigure(move |f| f.camera.position = [0.0, 1.0, 0.3]).unwrap()),
    ]);
    let many: Vec<String> = (0..10_000)
        .map(|i| {
            let a = i as f32 * 0.618;
            format!("[{:.3}, {:.3}, {:.3}, 0.5, 0.2]", 0.5 * a.sin(), 1.0 + 0.3 * a.cos(), 0.4 * (a * 0.7).sin())
        })
        .collect();
    sane_cases(&[("10^4 metaballs", puff(&many.join(", "), "", ""))]);
    let huge = common::scene_from_str(
        r#"
        [camera]
        position = [0.0, 10.0, 0.0]
        look_at = [0.0, 8000.0, -30000.0]
        vfov_deg = 50.0
        resolution = [32, 24]
        [sky]
        sun_zenith_deg = 30.0
        [[volume]]
        min = [-20000.0, 2000.0, -50000.0]
        max = [20000.0, 22000.0, -10000.0]
        sigma_s = [1e-4, 1e-4, 1e-4]
        sigma_t = [1e-4, 1e-4, 1e-4]
        metaballs = [[0.0, 12000.0, -30000.0, 10000.0, 1.0]]
        "#,
    );
    sane_cases(&[("radius 10 km", huge)]);
}

/// `assert_sane` on each case, drawn by slices and, where its volumes are
/// all metaballs, by splatting.
fn sane_cases(cases: &[(&str, SceneData)]) {
    for (what, data) in cases {
        assert_sane(what, data);
        let v = &data.volumes;
        if v.params.automaton_volume == 0 && !v.volumes.iter().any(|g| g.is_file_grid()) {
            assert_sane(&format!("{what}, splatted"), &splatted(data));
        }
    }
}

/// The sun at the horizon and below it: the cloud is lit by what reaches
/// it (nothing below the horizon) and still hides the sky.
#[test]
fn low_and_set_sun() {
    for zenith in [89.5f32, 90.0, 100.0] {
        let data = shipped("cloud_cumulus", 32, 24);
        let data = data.reconfigure(move |f| f.sky.as_mut().unwrap().sun_zenith_deg = zenith).unwrap();
        assert_sane(&format!("sun at {zenith} degrees"), &data);
    }
}

/// A scene without volumes runs none of the volumes' passes.
#[test]
fn a_scene_without_volumes_pays_nothing() {
    let data = slicelight::scene::load(&common::root().join("scenes/fog_spot.toml")).unwrap();
    for p in slicelight::render::plan(&data) {
        if p.name.starts_with("volume") {
            assert!(!p.ran, "{} runs without volumes: {}", p.name, p.reason);
        }
    }
}

fn load_error(toml: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    std::fs::write(dir.path().join("balls.txt"), "0 1 0 0.5 1\n0 1 0 0.5\n").unwrap();
    format!("{:#}", slicelight::scene::load(&path).unwrap_err())
}

/// Bad volumes are refused with the field named and what was expected.
#[test]
fn bad_volumes_name_the_field() {
    let base = r#"
        [camera]
        position = [0.0, 1.0, 6.0]
        look_at = [0.0, 1.0, 0.0]
        vfov_deg = 40.0
        resolution = [8, 8]
        [[volume]]
        sigma_s = [0.5, 0.5, 0.5]
        sigma_t = [1.0, 1.0, 1.0]
    "#;
    let cases = [
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 0.0, 1.0]", "volume[0].max"),
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nmetaballs = [[2.0, 0.5, 0.5, 0.3, 1.0]]", "volume[0].metaballs[0]"),
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nmetaballs = [[0.5, 0.5, 0.5, 0.0, 1.0]]", "radius"),
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nmetaballs = [[0.5, 0.5, 0.5, 0.3, -1.0]]", "q"),
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nmetaballs_file = \"balls.txt\"", "line 2"),
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nmetaballs_file = \"nope.txt\"", "nope.txt"),
        ("min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nresolution = [0, 4, 4]", "volume[0].resolution"),
        (
            "min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nphase = { kind = \"double-henyey-greenstein\", g1 = 0.8, g2 = 1.0, weight = 0.5 }",
            "volume[0].phase.g2",
        ),
    ];
    for (volume, field) in cases {
        let e = load_error(&format!("{base}\n{volume}"));
        assert!(e.contains(field), "{volume}: {e}");
    }
    let e = load_error(
        &format!("{base}\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]").replace("0.5, 0.5, 0.5]", "2.0, 0.5, 0.5]"),
    );
    assert!(e.contains("volume[0].sigma_s"), "{e}");
    let e = load_error(&format!(
        "{base}\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n[[point_light]]\nposition = [0.0, 3.0, 0.0]\nintensity = [1.0, 1.0, 1.0]"
    ));
    assert!(e.contains("point_light"), "{e}");
    let volume = "min = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]";
    for (settings, field) in [
        ("scattering = \"single\"\noctaves = 4", "volumes.octaves"),
        ("octaves = 4", "volumes.octaves"),
        ("scattering = \"octaves\"\noctaves = 0", "volumes.octaves"),
        ("column_width = 0.0", "volumes.column_width"),
        ("column_width = nan", "volumes.column_width"),
        ("scattering = \"octaves\"\ncolumn_width = 2.0", "volumes.column_width"),
        ("scattering = \"octaves\"\noctave_scattering = 0.9\noctave_extinction = 0.5", "volumes.octave_scattering"),
        ("scattering = \"octaves\"\noctave_phase = 1.5", "volumes.octave_phase"),
        ("scattering = \"all\"", "scattering"),
    ] {
        let e = load_error(&format!("{base}\n{volume}\n[volumes]\n{settings}"));
        assert!(e.contains(field), "{settings}: {e}");
    }
    // Splatting draws metaballs, and one method draws all volumes.
    let e = load_error(&format!(
        "{base}\n{volume}\nmethod = \"splatting\"\nautomaton = {{ cells = [4, 4, 4], steps = 2, seed = 1, {ELLIPSOID} }}"
    ));
    assert!(e.contains("volume[0].method") && e.contains("slices"), "{e}");
    let e = load_error(&format!("{base}\n{volume}\n[[volume]]\n{volume}\nsigma_s = [0.5, 0.5, 0.5]\nsigma_t = [1.0, 1.0, 1.0]\nmethod = \"splatting\""));
    assert!(e.contains("volume[1].method"), "{e}");
    let e = load_error(&format!("{base}\n{volume}\nmethod = \"billboards\""));
    assert!(e.contains("method"), "{e}");
}

/// The automaton's clouds with `scattering = "single"` at 48x36 pixel
/// centres against the f64 reference, whose field is the metaballs at the
/// lattice's centres evaluated exactly (the method trilinearly interpolates
/// the field sampled at those centres). Measured: see the print and
/// docs/volumes.md; the bound is the issue's 1 %.
#[test]
fn automaton_clouds_match_the_reference() {
    let (data, image, d, _) = single_against_reference("cloud_automaton", 48, 36, 1e-3);
    assert!(data.volumes.params.automaton_volume == 1);
    assert!(d.rms_8bit_percent < 1.0, "{d:?}");
    let changed = covered_pixels(&data, &image);
    assert!(changed > image.len() / 20, "the clouds cover {changed} of {} pixels", image.len());
}

/// A small automaton scene: `automaton` is the inline table's body.
fn automaton_scene(automaton: &str) -> SceneData {
    common::scene_from_str(&format!(
        r#"
        [camera]
        position = [0.0, 1.0, 12.0]
        look_at = [0.0, 1.0, 0.0]
        vfov_deg = 40.0
        resolution = [32, 24]
        [[directional_light]]
        direction = [0.3, -1.0, -0.4]
        irradiance = [2.0, 2.0, 2.0]
        [[volume]]
        min = [-3.0, 0.0, -3.0]
        max = [3.0, 2.0, 3.0]
        sigma_s = [0.9, 0.9, 0.9]
        sigma_t = [1.0, 1.0, 1.0]
        automaton = {{ {automaton} }}
        "#
    ))
}

const ELLIPSOID: &str =
    "ellipsoids = [{ center = [0.0, 1.0, 0.0], radii = [2.5, 1.0, 2.5], humidity = 0.2, activation = 0.02, extinction = 0.05 }]";

/// The automaton is a function of (cells, steps, seed): the same bits on a
/// second run, other bits for another seed; no supply, no clouds.
#[test]
fn automaton_is_deterministic() {
    use slicelight::shaders::volumes::automaton::CLD;
    use slicelight::volumes::automaton::run;
    let hidden = indicatif::ProgressBar::hidden();
    let a = automaton_scene(&format!("cells = [24, 8, 24], steps = 30, seed = 5, {ELLIPSOID}"));
    let first = run(&a.volumes.automaton, &hidden);
    assert_eq!(first, run(&a.volumes.automaton, &hidden));
    let clouds = first.iter().filter(|&&c| c & CLD != 0).count();
    assert!(clouds > 0 && clouds < first.len(), "{clouds} cloudy cells of {}", first.len());
    let b = automaton_scene(&format!("cells = [24, 8, 24], steps = 30, seed = 6, {ELLIPSOID}"));
    assert_ne!(first, run(&b.volumes.automaton, &hidden));
    let none = automaton_scene("cells = [24, 8, 24], steps = 30, ellipsoids = []");
    assert!(run(&none.volumes.automaton, &hidden).iter().all(|&c| c == 0));
}

/// One step against the rules written out here (Dobashi 2000 eqs. 1-4)
/// from a random lattice, with every probability 0 (growth alone), and a
/// wind of one cell a step shifting the result along x.
#[test]
fn automaton_step_follows_the_growth_rules() {
    use slicelight::shaders::random::random;
    use slicelight::shaders::volumes::automaton::{automaton_cell, ACT, CLD, HUM};
    let data = automaton_scene("cells = [12, 7, 9], steps = 1, ellipsoids = []");
    let mut p = data.volumes.automaton.params;
    let zero = vec![glam::UVec4::ZERO; p.cells as usize];
    let state: Vec<u32> = (0..p.cells).map(|i| random(i, 0, 99, 3) & 7).collect();
    let (nx, ny, nz) = (p.nx as i32, p.ny as i32, p.nz as i32);
    let at = |i: i32, j: i32, k: i32| -> u32 {
        if (0..nx).contains(&i) && (0..ny).contains(&j) && (0..nz).contains(&k) {
            state[((k * ny + j) * nx + i) as usize]
        } else {
            0
        }
    };
    for wind in [0, 256] {
        p.wind_x = wind;
        for c in 0..p.cells {
            let (i, j, k) = ((c % p.nx) as i32, ((c / p.nx) % p.ny) as i32, (c / (p.nx * p.ny)) as i32);
            let i = i - wind / 256;
            let s = at(i, j, k);
            let near = [
                (1, 0, 0),
                (-1, 0, 0),
                (2, 0, 0),
                (-2, 0, 0),
                (0, 0, 1),
                (0, 0, -1),
                (0, 0, 2),
                (0, 0, -2),
                (0, 1, 0),
                (0, -1, 0),
                (0, -2, 0),
            ];
            let f_act = near.iter().any(|(a, b, d)| at(i + a, j + b, k + d) & ACT != 0);
            let (hum, act, cld) = (s & HUM != 0, s & ACT != 0, s & CLD != 0);
            let want = (((hum && !act) as u32) * HUM)
                | (((!act && hum && f_act) as u32) * ACT)
                | (((cld || act) as u32) * CLD);
            assert_eq!(automaton_cell(c, 0, &p, &state, &zero), want, "cell {c}, wind {wind}");
        }
    }
}

/// The automaton at its edges: one cell, the widest smoothing, the
/// strongest wind, certain supply and certain extinction.
#[test]
fn automaton_stress_cases_stay_finite() {
    let sure = "ellipsoids = [{ center = [0.0, 1.0, 0.0], radii = [9.0, 9.0, 9.0], humidity = 1.0, activation = 1.0, extinction = 1.0 }]";
    sane_cases(&[
        ("one cell", automaton_scene(&format!("cells = [1, 1, 1], steps = 3, {ELLIPSOID}"))),
        ("smoothing 8", automaton_scene(&format!("cells = [16, 8, 16], steps = 20, smoothing = 8, {ELLIPSOID}"))),
        ("wind -8", automaton_scene(&format!("cells = [16, 8, 16], steps = 20, wind = [-8.0, 8.0], {ELLIPSOID}"))),
        ("certain everything", automaton_scene(&format!("cells = [16, 8, 16], steps = 20, ball_radius = 4.0, {sure}"))),
        ("no clouds", automaton_scene("cells = [16, 8, 16], steps = 5, ellipsoids = []")),
    ]);
}

/// Bad automata are refused with the field named.
#[test]
fn bad_automata_name_the_field() {
    let base = r#"
        [camera]
        position = [0.0, 1.0, 6.0]
        look_at = [0.0, 1.0, 0.0]
        vfov_deg = 40.0
        resolution = [8, 8]
        [[volume]]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 1.0]
        sigma_s = [0.5, 0.5, 0.5]
        sigma_t = [1.0, 1.0, 1.0]
    "#;
    let e = "ellipsoids = [{ center = [0.5, 0.5, 0.5], radii = [0.5, 0.5, 0.5], humidity = 0.1, activation = 0.1, extinction = 0.1 }]";
    for (automaton, field) in [
        (format!("cells = [0, 4, 4], steps = 1, {e}"), "volume[0].automaton.cells"),
        (format!("cells = [4, 4, 4], steps = 0, {e}"), "volume[0].automaton.steps"),
        // Over the most a frame may run: refused, not clamped (2^31 once ran
        // 100 000 steps for minutes).
        (format!("cells = [4, 4, 4], steps = 2147483648, {e}"), "volume[0].automaton.steps"),
        (format!("cells = [4, 4, 4], steps = 1, smoothing = 9, {e}"), "smoothing"),
        (format!("cells = [4, 4, 4], steps = 1, wind = [9.0, 0.0], {e}"), "wind"),
        (format!("cells = [4, 4, 4], steps = 1, ball_radius = 0.1, {e}"), "ball_radius"),
        ("cells = [4, 4, 4], steps = 1, ellipsoids = [{ center = [0.5, 0.5, 0.5], radii = [0.5, 0.0, 0.5], humidity = 0.1, activation = 0.1, extinction = 0.1 }]".to_string(), "ellipsoids[0].radii"),
        ("cells = [4, 4, 4], steps = 1, ellipsoids = [{ center = [0.5, 0.5, 0.5], radii = [0.5, 0.5, 0.5], humidity = 1.5, activation = 0.1, extinction = 0.1 }]".to_string(), "ellipsoids[0].humidity"),
    ] {
        let msg = load_error(&format!("{base}\nautomaton = {{ {automaton} }}"));
        assert!(msg.contains(field), "{automaton}: {msg}");
    }
    let msg = load_error(&format!(
        "{base}\nmetaballs = [[0.5, 0.5, 0.5, 0.2, 1.0]]\nautomaton = {{ cells = [4, 4, 4], steps = 1, {e} }}"
    ));
    assert!(msg.contains("volume[0].automaton"), "{msg}");
    let second =
        base.replace("[[volume]]", "[[volume]]\nautomaton = { cells = [4, 4, 4], steps = 1, ellipsoids = [] }");
    let msg = load_error(&format!("{second}\n[[volume]]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nsigma_s = [0.5, 0.5, 0.5]\nsigma_t = [1.0, 1.0, 1.0]\nautomaton = {{ cells = [4, 4, 4], steps = 1, {e} }}"));
    assert!(msg.contains("volume[1].automaton"), "{msg}");
}

/// The volumes' shadows on surfaces: the puff over the lit floor, single
/// scattering, at 48x32 pixel centres against the f64 reference (whose
/// shadow rays take the volumes' transmittance by a nested march), and the
/// floor darker under the puff than without it.
#[test]
fn volumes_shadow_the_surfaces() {
    // Seen from above on the side the shadow falls (the light travels
    // along +x, -z), so the shadow is not behind the puff.
    let data = puff(BALLS, "", "[volumes]\nscattering = \"single\"")
        .reconfigure(move |f| {
            f.camera.position = [3.0, 4.0, -4.0];
            f.camera.look_at = [0.3, 0.0, -0.4];
        })
        .unwrap();
    let r = slicelight::render::render_layers(&data, &Backend::Cpu, false).unwrap();
    let image = to_f64(&r.image);
    let (reference, _) = slicelight::reference::render_converged(&data, 1e-3);
    let d = difference(&image, &reference, data.exposure);
    println!(
        "puff over the floor 48x32: {:.3} % RMS, {:.3} % max of the 8-bit range",
        d.rms_8bit_percent, d.max_8bit_percent
    );
    assert!(d.rms_8bit_percent < 1.0, "{d:?}");
    let clear = data.reconfigure(move |f| f.volume[0].metaballs.clear()).unwrap();
    let lit = slicelight::render::render_layers(&clear, &Backend::Cpu, false).unwrap();
    let surface = |r: &slicelight::render::Rendered| -> Vec<glam::Vec4> {
        r.layers.iter().find(|(n, _)| *n == "surface").unwrap().1.as_slice::<glam::Vec4>().to_vec()
    };
    let (with, without) = (surface(&r), surface(&lit));
    let shaded = with.iter().zip(&without).filter(|(a, b)| a.x < 0.5 * b.x).count();
    // Measured: 12 of the 1536 pixels (the shadow seen beside the puff,
    // and the floor seen through it); without the volumes' transmittance
    // on the lights there are none.
    assert!(shaded >= 8, "{shaded} floor pixels in the puff's shadow");
}

/// The grid cloud (a Mitsuba `.vol` file) with `scattering = "single"` at
/// 48x36 pixel centres against the f64 reference, which interpolates the
/// file's values as Mitsuba 3 does: the method samples the same grid, so
/// what differs is the slices' and the transmittance volume's sampling.
/// Measured: see the print and docs/volumes.md; the bound is the issue's 1 %.
#[test]
fn grid_cloud_matches_the_reference() {
    let (data, _, d, _) = single_against_reference("cloud_grid", 48, 36, 1e-3);
    assert_eq!(data.volumes.volumes[0].nx, 48);
    assert!(d.rms_8bit_percent < 1.0, "{d:?}");
}

/// A grid file that is not one, or holds a negative density, is refused
/// with the file and the field named; a grid beside metaballs too.
#[test]
fn bad_grids_name_the_file_and_field() {
    use slicelight::volumes::grid::{vol_bytes, Grid};
    let dir = tempfile::tempdir().unwrap();
    let scene = |extra: &str| {
        format!(
            r#"
            [camera]
            position = [0.0, 1.0, 6.0]
            look_at = [0.0, 1.0, 0.0]
            vfov_deg = 40.0
            resolution = [8, 8]
            [[volume]]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 1.0]
            sigma_s = [0.5, 0.5, 0.5]
            sigma_t = [1.0, 1.0, 1.0]
            grid = {{ file = "g.vol" }}
            {extra}
            "#
        )
    };
    let load = |bytes: &[u8], extra: &str| {
        std::fs::write(dir.path().join("g.vol"), bytes).unwrap();
        let path = dir.path().join("s.toml");
        std::fs::write(&path, scene(extra)).unwrap();
        slicelight::scene::load(&path).map(|_| ()).map_err(|e| format!("{e:#}"))
    };
    let good = Grid { cells: [2, 2, 2], values: vec![0.5; 8] };
    assert!(load(&vol_bytes(&good), "").is_ok());
    let negative = Grid { cells: [2, 2, 2], values: vec![0.5, 0.5, 0.5, -1.0, 0.5, 0.5, 0.5, 0.5] };
    let e = load(&vol_bytes(&negative), "").unwrap_err();
    assert!(e.contains("volume[0].grid.file") && e.contains("g.vol") && e.contains("(1, 1, 0)"), "{e}");
    let e = load(b"VOL", "").unwrap_err();
    assert!(e.contains("g.vol"), "{e}");
    let e = load(&vol_bytes(&good), "metaballs = [[0.5, 0.5, 0.5, 0.2, 1.0]]").unwrap_err();
    assert!(e.contains("volume[0].grid"), "{e}");
    let e = load(&vol_bytes(&good), "resolution = [4, 4, 4]").unwrap_err();
    assert!(e.contains("volume[0].resolution"), "{e}");
}

/// The clouds' shadow on the sea: in `cloud_sea` (single scattering) each
/// pixel's order-1 sea light over the same scene without the cloud is the
/// sun's transmittance through the cloud at the surface point (times the
/// view's through the cloud, where the sea is seen through it), which the
/// reference marches in f64 through the grid's field. Measured: 225 pixels,
/// RMS 0.0040, worst 0.024 (on the shadow's edge); the bounds, 0.03 and
/// 0.2, allow the transmittance volume's trilinear interpolation there.
#[test]
fn clouds_shade_the_sea() {
    let data = shipped("cloud_sea", 64, 48)
        .reconfigure(move |f| f.volumes.scattering = slicelight::volumes::Scattering::Single)
        .unwrap();
    assert!(data.sea.params.sun_light > 0);
    let order1 = |d: &SceneData| -> Vec<glam::Vec4> {
        let r = slicelight::render::render_layers(d, &Backend::Cpu, false).unwrap();
        r.layers.iter().find(|(n, _)| *n == "sea.order1").unwrap().1.as_slice::<glam::Vec4>().to_vec()
    };
    let shaded = order1(&data);
    // The same scene with the cloud's box moved far behind the camera.
    let clear = data
        .reconfigure(move |f| {
            f.volume[0].min = [-900.0, 700.0, 90000.0];
            f.volume[0].max = [900.0, 1600.0, 91800.0];
        })
        .unwrap();
    let open = order1(&clear);
    assert_eq!(clear.sea.params.sun_light, data.sea.params.sun_light);
    let light = &data.lights[data.sea.params.sun_light as usize - 1];
    let (mut n, mut sum2, mut worst) = (0, 0.0f64, 0.0f64);
    for (i, (a, b)) in shaded.iter().zip(&open).enumerate() {
        if b.x <= 0.0 {
            continue;
        }
        let (o, d) = slicelight::shaders::camera::camera_ray(&data.common, i as u32 % 64, i as u32 / 64);
        let t = (data.sea.params.level - o.y) / d.y;
        let hit = (o + d * t).as_dvec3();
        let to_light = -light.axis_z.truncate().as_dvec3();
        let local_z = (hit - light.position.truncate().as_dvec3()).dot(light.axis_z.truncate().as_dvec3());
        // The layer is the light reaching the eye: seen through the cloud
        // too where the view ray crosses it.
        let view = slicelight::volumes::reference::transmittance_toward(&data, o.as_dvec3(), d.as_dvec3(), t as f64).x;
        let exact = view * slicelight::volumes::reference::transmittance_toward(&data, hit, to_light, local_z).x;
        let ratio = (a.x / b.x) as f64;
        if exact < 0.99 || ratio < 0.99 {
            n += 1;
            sum2 += (ratio - exact).powi(2);
            worst = worst.max((ratio - exact).abs());
        }
    }
    let rms = (sum2 / n.max(1) as f64).sqrt();
    println!("cloud_sea 64x48: {n} shaded sea pixels, transmittance ratio against the f64 march: RMS {rms:.4}, worst {worst:.4}");
    assert!(n > 20, "only {n} pixels of the sea in the cloud's shadow");
    assert!(rms < 0.03 && worst < 0.2, "rms {rms}, worst {worst}");
}

/// The clouds' shadow on the sun reflected by the sea: a flat sea whose
/// mirror image of the sun (a 3-degree disk, so that it covers pixels) lies
/// in view, a metaball (optical depth ~2 through its centre) 300 m up the
/// sun's ray from the mirror point. On 12 of the pixels where the reflected
/// sun is brightest, the image with the ball against the f64 reference,
/// which shades the reflected sun by its own march toward the sun (without
/// the ball the two agree within 0.01 %, held to 1 %). Unshaded, the
/// method's reflected sun there would be about 7 times the reference's.
/// The density grid and transmittance volume are finer than their defaults
/// (2.5 m cells, 128^3 nodes): at the defaults the small ball's optical
/// depth comes out 8 % low and the shaded sun 18 % bright (a leftover of
/// issue 23: the defaults' footprint rule), which is not what this test is
/// about. Measured: 0.85 % RMS, 1.12 % at worst; bounds 3 % and 6 %.
#[test]
fn clouds_shade_the_suns_reflection() {
    let scene = |ball_z: f32| {
        common::scene_from_str(&format!(
            r#"
            [camera]
            position = [0.0, 10.0, 0.0]
            look_at = [0.0, 0.0, -100.0]
            vfov_deg = 12.0
            resolution = [48, 32]
            exposure = 0.5
            [sky]
            sun_zenith_deg = 84.2894
            sun_azimuth_deg = 180.0
            sun_angular_radius_deg = 3.0
            [sea]
            water = "clear-ocean"
            [[volume]]
            min = [-60.0, 0.0, {lo}]
            max = [60.0, 80.0, {hi}]
            sigma_s = [0.04, 0.04, 0.04]
            sigma_t = [0.05, 0.05, 0.05]
            metaballs = [[0.0, 29.85, {ball_z}, 40.0, 1.0]]
            resolution = [48, 32, 48]
            [volumes]
            scattering = "single"
            light_grid = [128, 128, 128]
            "#,
            lo = ball_z - 60.0,
            hi = ball_z + 60.0
        ))
    };
    let data = scene(-398.5);
    // The ball far behind the camera: the same sky, an open sun.
    let open = cpu_image(&scene(5000.0));
    let shaded = cpu_image(&data);
    let brightest = open.iter().map(|p| p.x).fold(0.0f32, f32::max);
    let glint: Vec<u32> = (0..open.len() as u32).filter(|&i| open[i as usize].x > 0.2 * brightest).collect();
    assert!(glint.len() >= 4, "the reflected sun covers {} pixels", glint.len());
    let glint: Vec<u32> = glint.iter().copied().step_by(glint.len().div_ceil(12)).collect();
    let (reference, _) = slicelight::reference::render_converged_at(&data, &glint, 2e-4);
    let (open_reference, _) = slicelight::reference::render_converged_at(&scene(5000.0), &glint, 2e-4);
    // Without the ball the method's reflected sun is the reference's.
    for (k, &i) in glint.iter().enumerate() {
        let e = (open[i as usize].x as f64 - open_reference[k].x).abs() / open_reference[k].x;
        assert!(e < 0.01, "pixel {i}, open sea: {} against {}", open[i as usize].x, open_reference[k].x);
    }
    let (mut sum2, mut worst, mut dimmed) = (0.0f64, 0.0f64, 0.0f64);
    for (k, &i) in glint.iter().enumerate() {
        let got = shaded[i as usize].x as f64;
        let want = reference[k].x;
        let e = (got - want).abs() / want;
        sum2 += e * e;
        worst = worst.max(e);
        dimmed = dimmed.max(got / open[i as usize].x as f64);
    }
    let rms = (sum2 / glint.len() as f64).sqrt();
    println!(
        "the sun's reflection under a ball: {} pixels, against the f64 reference {:.2} % RMS, {:.2} % at worst; at most {:.3} of the open sea",
        glint.len(),
        100.0 * rms,
        100.0 * worst,
        dimmed
    );
    assert!(dimmed < 0.5, "the ball's shadow does not dim the reflected sun: {dimmed}");
    assert!(rms < 0.03 && worst < 0.06, "rms {rms}, worst {worst}");
}

/// The volumes' shadows in the fog: a puff high over a floor in a
/// scattering medium under the directional light (single scattering), seen
/// from the side, where view rays cross the puff's shadow without crossing
/// its box. On those pixels the image is the fog's light
/// alone, and the reference's (fog samples marching toward the light
/// through the analytic field) is measurably darker than the fog without
/// the puff: the method must follow it, not the unshadowed fog. Measured:
/// 0.0015 RMS of the peak against a shadow of 0.0117; with the fog's
/// shadows switched off in the shafts pass, 0.0062 (the test then fails).
#[test]
fn volumes_shadow_the_fog() {
    // A puff high over the floor, in its own box: the shadow's column
    // below the box is seen from the side by rays that miss the box.
    let data = fog_puff(
        "position = [6.0, 1.0, 3.0]\nlook_at = [0.3, 1.0, -0.4]",
        [48, 32],
        [0.3, 0.35],
        "min = [-1.0, 2.0, -1.0]\nmax = [1.0, 4.0, 1.0]\nsigma_s = [3.0, 3.0, 3.0]\nsigma_t = [3.0, 3.0, 3.0]\nmetaballs = [[0.0, 3.0, 0.0, 0.9, 1.0]]",
    );
    let outside = pixels_by_box(&data, false);
    let image = to_f64(&cpu_image(&data));
    let (reference, _) = slicelight::reference::render_converged_at(&data, &outside, 1e-3);
    let clear = data.reconfigure(move |f| f.volume[0].metaballs.clear()).unwrap();
    let (unshadowed, _) = slicelight::reference::render_converged_at(&clear, &outside, 1e-3);
    let method: Vec<_> = outside.iter().map(|&i| image[i as usize]).collect();
    let (rms, _) = slicelight::metrics::relative_error(&method, &reference);
    let (shadow, _) = slicelight::metrics::relative_error(&unshadowed, &reference);
    println!(
        "puff in fog, {} pixels beside the box: method against reference {:.4} RMS (of the peak); the puff's shadow {:.4}",
        outside.len(),
        rms,
        shadow
    );
    assert!(shadow > 0.005, "the view must cross the shadow: {shadow}");
    assert!(rms < 0.25 * shadow, "{rms} against a shadow of {shadow}");
}

/// Fog in front of a volume is not hidden by it: a puff in a scattering
/// medium seen by rays that cross its box, against the reference, which
/// sees each fog sample through the volumes in front of it only. Measured:
/// 0.215 % RMS, 0.78 % max (8-bit), energy 1.006 over 100 pixels; with
/// the shafts' `Pass::spans_the_view_ray` false, when the fog in front is
/// dimmed by the whole crossing as the fog behind is, 2.62 % RMS and
/// energy 0.844 (the bound, 1 %, fails that: checked). What is left is the fog's
/// light weighted as if uniform along the ray.
#[test]
fn fog_in_front_of_a_volume_is_not_hidden() {
    let data = fog_puff(
        "position = [0.0, 1.5, 9.0]\nlook_at = [0.0, 1.5, 0.0]",
        [40, 30],
        [0.1, 0.12],
        "min = [-1.0, 0.5, -1.0]\nmax = [1.0, 2.5, 1.0]\nsigma_s = [4.0, 4.0, 4.0]\nsigma_t = [4.0, 4.0, 4.0]\nmetaballs = [[0.0, 1.5, 0.0, 0.95, 1.0]]",
    );
    let through = pixels_by_box(&data, true);
    let image = to_f64(&cpu_image(&data));
    let (reference, _) = slicelight::reference::render_converged_at(&data, &through, 1e-3);
    let method: Vec<_> = through.iter().map(|&i| image[i as usize]).collect();
    let d = difference(&method, &reference, data.exposure);
    println!(
        "fog around a puff, {} pixels through its box: {:.3} % RMS, {:.3} % max (8-bit), energy {:.4}",
        through.len(),
        d.rms_8bit_percent,
        d.max_8bit_percent,
        d.energy_ratio
    );
    assert!(through.len() > 50);
    assert!(d.rms_8bit_percent < 1.0, "{d:?}");
}

/// A puff in fog over a floor under a directional light, single
/// scattering: `camera` and `volume` are the `[camera]` position/look-at
/// lines and the `[[volume]]` box, sigma and metaballs lines.
fn fog_puff(camera: &str, resolution: [u32; 2], fog: [f32; 2], volume: &str) -> SceneData {
    common::scene_from_str(&format!(
        r#"
        [camera]
        {camera}
        vfov_deg = 40.0
        resolution = [{}, {}]
        [medium]
        sigma_s = [{s}, {s}, {s}]
        sigma_t = [{t}, {t}, {t}]
        [[directional_light]]
        direction = [0.3, -1.0, -0.4]
        irradiance = [2.0, 2.0, 2.0]
        [[object]]
        type = "quad"
        center = [0.0, 0.0, 0.0]
        u = [8.0, 0.0, 0.0]
        v = [0.0, 0.0, 8.0]
        [[volume]]
        {volume}
        [volumes]
        scattering = "single"
        "#,
        resolution[0],
        resolution[1],
        s = fog[0],
        t = fog[1],
    ))
}

/// The pixels whose centre ray crosses (`crossing`) or misses the first
/// volume's box.
fn pixels_by_box(data: &SceneData, crossing: bool) -> Vec<u32> {
    let (w, h) = (data.width(), data.height());
    let v = &data.volumes.volumes[0];
    (0..w * h)
        .filter(|&i| {
            let (o, d) = slicelight::shaders::camera::camera_ray(&data.common, i % w, i / w);
            let (near, far) = slicelight::shaders::geometry::box_span(
                o,
                glam::Vec3::ONE / d,
                v.min.truncate(),
                v.max.truncate(),
                0.0,
                f32::MAX,
            );
            (near < far) == crossing
        })
        .collect()
}

#[test]
fn the_automaton_steps_with_the_scene_time() {
    // `steps_per_second` adds steps with time (a time-lapse); without it
    // the clouds are the same at every instant. A negative rate is refused.
    let body = "cells = [8, 4, 8]\nsteps = 10\nsteps_per_second = 4.0\nellipsoids = []";
    let s: slicelight::volumes::automaton::Settings = toml::from_str(body).unwrap();
    let (lo, hi) = (glam::Vec3::ZERO, glam::Vec3::splat(8.0));
    let at = |t: f64| slicelight::volumes::automaton::configure_at("volume[0]", 0, &s, lo, hi, t).unwrap().steps;
    assert_eq!((at(0.0), at(2.5), at(10.0)), (10, 20, 50));
    let mut still = s.clone();
    still.steps_per_second = None;
    assert_eq!(slicelight::volumes::automaton::configure_at("v", 0, &still, lo, hi, 10.0).unwrap().steps, 10);
    still.steps_per_second = Some(-1.0);
    let err = slicelight::volumes::automaton::configure_at("volume[0]", 0, &still, lo, hi, 1.0).unwrap_err();
    assert!(err.to_string().starts_with("volume[0].automaton.steps_per_second"), "{err}");
}

/// Light of irradiance 1 entering a plane-parallel slab `depth` optical
/// depths thick along its normal, by exact 1D transport in f64: photons
/// fly exponential free paths, scatter with albedo `omega` by the
/// Henyey-Greenstein phase function `g` (no delta scaling, no P1: none of
/// `column_channel`'s shortcuts). Returns the reflected and transmitted
/// shares (direct included) and their standard errors.
fn slab_monte_carlo(omega: f64, g: f64, depth: f64, photons: u32, seed: u64) -> ((f64, f64), (f64, f64)) {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let (mut up, mut down) = (0u32, 0u32);
    for _ in 0..photons {
        let (mut z, mut mu) = (0.0f64, 1.0f64);
        loop {
            z += mu * -(1.0 - rng.random::<f64>()).ln();
            if z < 0.0 {
                up += 1;
                break;
            }
            if z > depth {
                down += 1;
                break;
            }
            if rng.random::<f64>() >= omega {
                break;
            }
            // Henyey-Greenstein's cosine to the old direction, then the new
            // direction's cosine to the slab normal.
            let xi: f64 = rng.random();
            let cos = if g.abs() < 1e-6 {
                2.0 * xi - 1.0
            } else {
                let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
                (1.0 + g * g - s * s) / (2.0 * g)
            };
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            let phi = 2.0 * std::f64::consts::PI * rng.random::<f64>();
            mu = (mu * cos + (1.0 - mu * mu).max(0.0).sqrt() * sin * phi.cos()).clamp(-1.0, 1.0);
        }
    }
    let share = |k: u32| {
        let p = k as f64 / photons as f64;
        (p, (p * (1.0 - p) / photons as f64).sqrt())
    };
    (share(up), share(down))
}

/// `column_channel`'s reflected and transmitted light against exact 1D
/// transport (`slab_monte_carlo`) for cloud droplets (albedo 0.99 and
/// 0.9, Henyey-Greenstein g = 0.85) from optical depth 1 to 64, with no
/// lateral leakage (width 1e6). The delta-Eddington approximation's own
/// error is a few hundredths of the incident light at normal incidence
/// (Joseph, Wiscombe and Weinman 1976 report up to 0.03-0.05 for thin
/// layers). Measured: within 0.0096 of the exact shares in all eight
/// cases (100 000 photons each); the bound is 0.015 plus four standard
/// errors. A sign or factor slip in the boundary conditions moves the
/// reflectance by tenths.
#[test]
fn columns_match_exact_slab_transport() {
    use slicelight_shaders::volumes::column_channel;
    for omega in [0.99f32, 0.9] {
        for depth in [1.0f32, 4.0, 16.0, 64.0] {
            let g = 0.85f32;
            let (_, fluence_top, _) = column_channel(omega, g, g * g, 0.0, depth, 1e6);
            // Marshak's conditions: the diffuse light leaving a face is half
            // the fluence there; the direct beam's (scaled) remainder leaves
            // the far face.
            let (scaled_direct, fluence_bottom, _) = column_channel(omega, g, g * g, depth, depth, 1e6);
            let reflected = 0.5 * fluence_top as f64;
            let transmitted = 0.5 * fluence_bottom as f64 + scaled_direct as f64;
            let ((r, r_se), (t, t_se)) = slab_monte_carlo(omega as f64, g as f64, depth as f64, 100_000, 7);
            println!(
                "omega {omega} g {g} depth {depth}: reflected {reflected:.4} (exact {r:.4} +- {r_se:.4}), transmitted {transmitted:.4} (exact {t:.4} +- {t_se:.4})"
            );
            assert!((reflected - r).abs() < 0.015 + 4.0 * r_se, "reflected {reflected} against {r}");
            assert!((transmitted - t).abs() < 0.015 + 4.0 * t_se, "transmitted {transmitted} against {t}");
        }
    }
}

/// `column_channel` at the edges of its parameters: albedo 0 to 1 (1 is
/// held at `MAX_COLUMN_ALBEDO`), asymmetry -0.9 to 0.95, depths 0 to 10^4,
/// widths 1e-3 to 1e6, and the particular solution's singular `k = 1`
/// (albedo 0.6, g 0: `3 (1 - w) = 1.2` before the lateral term; the sweep
/// over widths crosses it). Everything finite and the direct beam in
/// [0, 1]; no light created: what leaves both faces plus the direct beam
/// is at most what entered (Marshak's half-fluences), and without
/// absorption or lateral leakage it is all of it up to depth 10, within
/// what `MAX_COLUMN_ALBEDO` absorbs (1e-4 of the fluence, at most 3 here,
/// per unit depth) plus 1e-3 for f32.
#[test]
fn columns_conserve_energy_at_the_edges() {
    use slicelight_shaders::volumes::{column_channel, MAX_COLUMN_ALBEDO};
    for omega in [0.0f32, 0.3, 0.6, 0.9, 0.99, 1.0] {
        for g in [-0.9f32, -0.3, 0.0, 0.58, 0.85, 0.95] {
            for depth in [0.0f32, 1e-4, 0.1, 1.0, 10.0, 100.0, 1e4] {
                // 0: no lateral leakage at all (the ring's columns, `diffuse_node`).
                for width in [0.0f32, 1e-3, 0.3, 1.0, 1.75, 10.0, 1e6] {
                    let at = |tau: f32| column_channel(omega, g, g * g, tau, depth, width);
                    for tau in [0.0, 0.5 * depth, depth] {
                        let (d, f, j) = at(tau);
                        assert!(d.is_finite() && f.is_finite() && j.is_finite(), "{omega} {g} {depth} {width} {tau}");
                        assert!((0.0..=1.0).contains(&d), "direct {d}");
                    }
                    let (_, top, _) = at(0.0);
                    let (direct, bottom, _) = at(depth);
                    let out = 0.5 * (top + bottom) + direct;
                    assert!(out <= 1.0 + 1e-3, "{omega} {g} {depth} {width}: {out} leaves");
                    if omega >= MAX_COLUMN_ALBEDO && (width >= 1e6 || width == 0.0) && depth <= 10.0 {
                        let held = (1.0 - MAX_COLUMN_ALBEDO) * 3.0 * depth + 1e-3;
                        assert!((out - 1.0).abs() < held, "{g} {depth}: {out} leaves without absorption");
                    }
                }
            }
        }
    }
}

/// OpenVDB float grids (`tests/data/*.vdb`, written by OpenVDB 10 through
/// `scripts/vdb_files.py`) load as dense grids over their active voxels'
/// bounds, each voxel's value in its cell: a grid of 6 x 4 x 3 voxels
/// whose values tell their place (chosen as "density" beside another
/// grid, or the other by name), 8^3 tiles expanded voxel by voxel, and
/// 256^3 voxels (over the 2^23 cells a grid gets)
/// box-filtered 2x per axis.
#[test]
fn vdb_grids_load_as_their_voxels() {
    use slicelight::volumes::grid::read_vdb;
    let data = common::root().join("tests/data");
    let limit = slicelight::volumes::MAX_DEFAULT_CELLS;
    let small = read_vdb("grid", &data.join("small.vdb"), None, limit).unwrap();
    assert_eq!(small.cells, [6, 4, 3]);
    for k in 0..3 {
        for j in 0..4 {
            for i in 0..6 {
                let expected = 1.0 + i as f32 + 10.0 * j as f32 + 100.0 * k as f32;
                assert_eq!(small.values[(k * 4 + j) * 6 + i], expected, "voxel ({i}, {j}, {k})");
            }
        }
    }
    let other = read_vdb("grid", &data.join("small.vdb"), Some("temperature"), limit).unwrap();
    assert_eq!((other.cells, other.values), ([1, 1, 1], vec![3.0]));
    let tiles = read_vdb("grid", &data.join("tiles.vdb"), None, limit).unwrap();
    assert_eq!(tiles.cells, [16, 8, 8]);
    for (c, v) in tiles.values.iter().enumerate() {
        let expected = if c == (3 * 8 + 3) * 16 + 3 { 2.0 } else { 0.25 };
        assert_eq!(*v, expected, "cell {c}");
    }
    let big = read_vdb("grid", &data.join("big.vdb"), None, limit).unwrap();
    assert_eq!(big.cells, [128, 128, 128]);
    assert!(big.values.iter().all(|&v| v == 1.0));
}

/// Bad OpenVDB input names the field and the file and says what was
/// expected: a vector grid, a negative density (with its voxel), a grid
/// saved as half floats (which vdb-rs 0.6 misreads into an abort), a grid
/// name the file lacks (listing the ones it has), `name` on a `.vol`
/// file, and a file that is not OpenVDB at all.
#[test]
fn bad_vdb_files_name_the_field() {
    let data = common::root().join("tests/data");
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("text.vdb"), "not a vdb file, only some text in it").unwrap();
    for name in ["vector.vdb", "negative.vdb", "small.vdb", "half.vdb"] {
        std::fs::copy(data.join(name), dir.path().join(name)).unwrap();
    }
    let error = |grid: &str| {
        let toml = format!(
            "[camera]\nposition = [0.0, 1.0, 6.0]\nlook_at = [0.0, 1.0, 0.0]\nvfov_deg = 40.0\nresolution = [8, 8]\n\
             [[volume]]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nsigma_s = [0.5, 0.5, 0.5]\nsigma_t = [1.0, 1.0, 1.0]\n\
             grid = {grid}\n"
        );
        let path = dir.path().join("scene.toml");
        std::fs::write(&path, toml).unwrap();
        format!("{:#}", slicelight::scene::load(&path).unwrap_err())
    };
    let cases = [
        ("{ file = \"vector.vdb\" }", ["volume[0].grid.file", "vector.vdb", "float grid"]),
        ("{ file = \"negative.vdb\" }", ["volume[0].grid.file", "voxel (1, 2, 3)", "-0.5"]),
        ("{ file = \"half.vdb\" }", ["volume[0].grid.file", "half.vdb", "half floats"]),
        ("{ file = \"small.vdb\", name = \"smoke\" }", ["volume[0].grid.name", "\"smoke\"", "\"temperature\""]),
        ("{ file = \"g.vol\", name = \"density\" }", ["volume[0].grid.name", ".vol", "one grid"]),
        ("{ file = \"text.vdb\" }", ["volume[0].grid.file", "text.vdb", "OpenVDB"]),
        ("{ file = \"missing.vdb\" }", ["volume[0].grid.file", "missing.vdb", ""]),
    ];
    for (grid, words) in cases {
        let e = error(grid);
        for w in words {
            assert!(e.contains(w), "{grid}: {e}");
        }
    }
}

/// `cloud_vdb.toml` reads `scenes/cloud_grid.vdb`, the same values as
/// `cloud_grid.vol` in an OpenVDB file: the two scenes' images are the
/// same bits.
#[test]
fn a_vdb_cloud_renders_as_its_vol_file() {
    let vdb = shipped("cloud_vdb", 64, 48);
    let vol = shipped("cloud_grid", 64, 48);
    assert_eq!(cpu_image(&vdb), cpu_image(&vol));
}
