//! The smoke family's fluid: the projection's divergence, the Taylor-Green
//! vortex's viscous decay, the smoke's conservation in a closed box, a hot
//! sphere's first acceleration against potential flow, and stress at the
//! edges of the parameters.

use glam::{UVec3, Vec3};
use indicatif::ProgressBar;
use slicelight::shaders::smoke::{coords, position};
use slicelight::smoke::reference::{buoyant_sphere, taylor_green};
use slicelight::smoke::{self, Advection, Config, Settings};

/// Settings from the body of a `smoke = { ... }` table.
fn settings(body: &str) -> Settings {
    toml::from_str(body).unwrap_or_else(|e| panic!("{body}: {e}"))
}

/// A validated configuration over the box `[lo, hi]`.
fn config(body: &str, lo: Vec3, hi: Vec3) -> Config {
    smoke::configure("volume[0]", &settings(body), lo, hi).unwrap_or_else(|e| panic!("{e}"))
}

/// The effective viscosity of the Taylor-Green vortex on `n x n` cells.
fn taylor_green_viscosity(n: u32, nu: f32, advection: &str, seconds: f32) -> f64 {
    let scheme = if advection == "maccormack" { Advection::Maccormack } else { Advection::SemiLagrangian };
    let tg = taylor_green(n, nu, scheme, seconds);
    assert!(tg.divergence <= 1e-5, "divergence {} in the Taylor-Green run", tg.divergence);
    tg.viscosity
}

#[test]
fn taylor_green_decay_converges_to_the_given_viscosity() {
    // The solver's effective viscosity is the given one plus the numerical
    // diffusion of the advection's interpolation, which falls with the cell
    // size: the error at 64 cells must be well under that at 32 (first
    // order for semi-Lagrangian: about half; MacCormack: less).
    let nu = 0.02;
    let mut fine_errors = Vec::new();
    for advection in ["semi-lagrangian", "maccormack"] {
        let coarse = taylor_green_viscosity(32, nu, advection, 1.0);
        let fine = taylor_green_viscosity(64, nu, advection, 1.0);
        let (ec, ef) = ((coarse - nu as f64).abs(), (fine - nu as f64).abs());
        println!("{advection}: nu_eff {coarse:.5} at 32^2, {fine:.5} at 64^2 (given {nu}); errors {ec:.2e} {ef:.2e}");
        assert!(ef < 0.7 * ec, "{advection}: no convergence: {ec:.3e} at 32, {ef:.3e} at 64");
        fine_errors.push(ef);
    }
    assert!(fine_errors[1] < 0.5 * fine_errors[0], "MacCormack should halve the numerical viscosity: {fine_errors:?}");
}

#[test]
fn projection_leaves_no_divergence_around_an_obstacle_with_open_faces() {
    // A random velocity field in a box with a solid block and the default
    // walls (floor only): after one projection, max |div u| h / max |u|
    // is at most 1e-5 (the issue's bound; the solver's own stop is 1e-6).
    let n = 24;
    let c = config(&format!("cells = [{n}, {n}, {n}]\nwind = [1.0, 0.0, 0.0]"), Vec3::ZERO, Vec3::splat(2.4));
    let mut cells = vec![1u32; (n * n * n) as usize];
    for (i, f) in cells.iter_mut().enumerate() {
        let x = coords(UVec3::splat(n), i as u32);
        if (8..14).contains(&x.x) && x.y < 10 && (6..16).contains(&x.z) {
            *f = 0;
        }
    }
    let mut f = c.start(cells);
    let mut state = 12345u32;
    f.set_velocity(|_, _| {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    });
    let before = f.max_divergence() / f.max_speed();
    let st = f.project();
    println!("relative divergence {before:.3} -> {:.2e} in {} iterations", st.divergence, st.solve.iterations);
    assert!(before > 0.1, "the random field should start divergent: {before}");
    assert!(st.solve.converged, "{st:?}");
    assert!(st.divergence <= 1e-5, "{st:?}");
}

#[test]
fn smoke_in_a_closed_box_is_conserved_within_the_stated_bound() {
    // A hot blob of smoke rising and rolling in a closed box, no source.
    // Semi-Lagrangian and MacCormack advection are not conservative: the
    // total changes by the interpolation's error. Measured: at most 0.63 %
    // (semi-Lagrangian) and 0.87 % (MacCormack) a step, 12 % and 18 % over
    // the 60 steps as the blob spreads under the lid; the bound is 1 % a
    // step. (Puffs, the default render, carry a fixed amount each.)
    for advection in ["semi-lagrangian", "maccormack"] {
        let n = 32;
        let c = config(
            &format!("cells = [{n}, {n}, {n}]\nwalls = \"closed\"\ndt = 0.05\nadvection = \"{advection}\""),
            Vec3::ZERO,
            Vec3::splat(3.2),
        );
        let mut f = c.start(vec![1; (n * n * n) as usize]);
        let centre = Vec3::new(1.6, 0.9, 1.6);
        for i in 0..f.params.cells {
            let x = (position(3, coords(UVec3::splat(n), i)) * f.params.h - centre).length();
            if x < 0.6 {
                f.smoke[i as usize] = 1.0;
                f.temperature[i as usize] = 400.0;
            }
        }
        let m0 = f.total_smoke();
        let mut worst_step = 0.0f64;
        for _ in 0..60 {
            let before = f.total_smoke();
            f.step();
            worst_step = worst_step.max((f.total_smoke() / before - 1.0).abs());
        }
        let drift = (f.total_smoke() / m0 - 1.0).abs();
        println!(
            "{advection}: worst change per step {:.3} %, after 60 steps {:.3} %, max speed {:.2} m/s",
            100.0 * worst_step,
            100.0 * drift,
            f.max_speed()
        );
        assert!(f.max_speed() > 0.2, "the blob should rise: {}", f.max_speed());
        assert!(worst_step < 0.01, "{advection}: {worst_step}");
    }
}

#[test]
fn a_hot_sphere_starts_to_rise_at_two_thirds_of_its_buoyancy() {
    // Potential flow: a sphere of fluid lighter by g' (Boussinesq) starts
    // from rest with acceleration g' / (1 + C_m), C_m = 1/2 the added mass
    // of a sphere, so 2 g' / 3 at its centre. One short step (no velocity
    // to advect yet) on a sphere of 8 cells' radius in a box 8 radii wide;
    // 3 % for the voxelised sphere and the walls at 4 radii (measured: 1 %).
    let (rise, expected) = buoyant_sphere(64);
    println!("acceleration at the centre {rise:.4} m/s^2, 2 g'/3 = {expected:.4}");
    assert!((rise / expected - 1.0).abs() < 0.03, "{rise}");
}

#[test]
fn stress_large_steps_hot_and_cold_sources_thin_grids_and_sources_inside_obstacles() {
    // dt 100 times the CFL limit, sources at 0 K and 1e4 K, a grid one cell
    // thick, a source inside a solid block: every value finite, the
    // temperature within the sources' and the ambient's range (advection
    // and implicit diffusion blend, they never extrapolate), the
    // projection still converged.
    let cases = [
        ("cells = [16, 16, 16]\ndt = 2.0\n[[source]]\nposition = [0.8, 0.3, 0.8]\nradius = 0.2\nrate = 5.0\ntemperature = 10000.0\nvelocity = [0.0, 3.0, 0.0]", false),
        ("cells = [16, 16, 16]\ndt = 0.05\n[[source]]\nposition = [0.8, 0.3, 0.8]\nradius = 0.2\nrate = 5.0\ntemperature = 0.0", false),
        ("cells = [16, 1, 16]\ndt = 0.05\n[[source]]\nposition = [0.8, 0.05, 0.8]\nradius = 0.2\nrate = 5.0\ntemperature = 600.0", false),
        ("cells = [16, 16, 16]\ndt = 0.05\nturbulence = 5.0\ntemperature_noise = 50.0\neddy_diffusivity = 0.01\neddy_viscosity = 0.01\n[[source]]\nposition = [0.8, 0.3, 0.8]\nradius = 0.2\nrate = 5.0\ntemperature = 600.0", true),
    ];
    for (body, blocked) in cases {
        let s = settings(body);
        let ny = s.cells[1] as f32;
        let c = smoke::configure("volume[0]", &s, Vec3::ZERO, Vec3::new(1.6, 0.1 * ny, 1.6)).unwrap();
        let mut cells = vec![1u32; c.params.cells as usize];
        if blocked {
            // A block around the source.
            for (i, f) in cells.iter_mut().enumerate() {
                let x = coords(c.params.dims(), i as u32);
                if (5..11).contains(&x.x) && x.y < 6 && (5..11).contains(&x.z) {
                    *f = 0;
                }
            }
        }
        let mut f = c.start(cells);
        let (lo, hi) = s
            .source
            .iter()
            .fold((f.params.ambient, f.params.ambient), |(a, b), s| (a.min(s.temperature), b.max(s.temperature)));
        for _ in 0..20 {
            f.step();
            let finite = [&f.u, &f.v, &f.w, &f.temperature, &f.smoke].iter().all(|q| q.iter().all(|x| x.is_finite()));
            assert!(finite, "{body}: a value not finite at step {}", f.params.step);
            let (tl, th) = f.temperature.iter().fold((f32::MAX, f32::MIN), |(a, b), &t| (a.min(t), b.max(t)));
            let noise = 6.0 * 2.0 * f.params.temperature_noise * f.params.eddy_diffusivity * f.params.dt
                / (f.params.h * f.params.h)
                * f.params.step as f32;
            assert!(tl >= lo - 1e-3 * lo.max(1.0) - noise && th <= hi * 1.001 + noise, "{body}: T in [{tl}, {th}]");
            assert!(f.last.solve.converged || f.last.divergence <= 1e-5, "{body}: {:?}", f.last);
            // No growth beyond what the forces can give: the largest
            // buoyancy and random acceleration over the time so far, plus
            // the sources' speed (an unstable step grows geometrically).
            let p = f.params;
            let t = p.dt * p.step as f32;
            let bound = (p.gravity * (hi / p.ambient - 1.0).abs().max(1.0) + p.turbulence) * t
                + s.source.iter().map(|s| Vec3::from(s.velocity).length()).sum::<f32>();
            assert!(f.max_speed() <= bound as f64 * 1.01, "{body}: {} m/s over {bound}", f.max_speed());
        }
        if blocked {
            let solid_smoke: f32 = f.smoke.iter().zip(&f.fluid).filter(|(_, c)| **c == 0).map(|(s, _)| *s).sum();
            assert_eq!(solid_smoke, 0.0, "smoke inside the obstacle");
        }
        println!("{}: {} puffs, max speed {:.2} m/s", body.lines().nth(1).unwrap_or(""), f.puffs.len(), f.max_speed());
    }
}

#[test]
fn grids_too_large_are_refused_with_the_memory_they_need() {
    let s = settings("cells = [512, 512, 512]");
    let err = smoke::configure("volume[0]", &s, Vec3::ZERO, Vec3::splat(5.12)).unwrap_err().to_string();
    assert!(err.contains("volume[0].smoke.cells") && err.contains("GiB"), "{err}");
    // 256^3 is accepted (the limit); not run here (1.3 GiB, minutes a step on two cores).
    let s = settings("cells = [256, 256, 256]");
    smoke::configure("volume[0]", &s, Vec3::ZERO, Vec3::splat(2.56)).unwrap();
    // Non-cubic cells, a source outside the box, a negative rate.
    for (body, field) in [
        ("cells = [10, 20, 10]", "volume[0].smoke.cells"),
        ("cells = [10, 10, 10]\n[[source]]\nposition = [5.0, 0.0, 0.0]\nradius = 0.1\nrate = 1.0\ntemperature = 300.0", "volume[0].smoke.source[0].position"),
        ("cells = [10, 10, 10]\n[[source]]\nposition = [0.5, 0.5, 0.5]\nradius = 0.1\nrate = -1.0\ntemperature = 300.0", "volume[0].smoke.source[0].rate"),
        ("cells = [10, 10, 10]\ndt = 0.0", "volume[0].smoke.dt"),
    ] {
        let err = smoke::configure("volume[0]", &settings(body), Vec3::ZERO, Vec3::ONE).unwrap_err().to_string();
        assert!(err.starts_with(field), "{body}: {err}");
    }
}

#[test]
fn continuing_a_kept_simulation_gives_the_same_state_as_starting_again() {
    // Determinism across animation frames: 10 steps then 10 more equal 20
    // steps from rest, bit for bit (random components included).
    let body = "cells = [12, 12, 12]\nturbulence = 2.0\ntemperature_noise = 5.0\neddy_diffusivity = 0.01\n[[source]]\nposition = [0.6, 0.2, 0.6]\nradius = 0.2\nrate = 10.0\ntemperature = 500.0";
    let c = config(body, Vec3::ZERO, Vec3::splat(1.2));
    let cells = vec![1u32; 12 * 12 * 12];
    let hidden = ProgressBar::hidden();
    let dt = c.params.dt as f64;
    let _ten = smoke::simulate(&c, cells.clone(), 10.0 * dt, &hidden).expect("the CPU steps");
    let continued = smoke::simulate(&c, cells.clone(), 20.0 * dt, &hidden).expect("the CPU steps");
    let mut fresh = c.start(cells);
    for _ in 0..20 {
        fresh.step();
    }
    assert_eq!(continued.params.step, 20);
    assert_eq!(continued.u, fresh.u);
    assert_eq!(continued.temperature, fresh.temperature);
    assert_eq!(continued.puffs, fresh.puffs);
    assert!(!fresh.puffs.is_empty());
}

#[test]
fn every_step_of_the_shipped_smoke_scenes_is_divergence_free() {
    // max |div u| h / max |u| <= 1e-5 after every projection, with the
    // scene's obstacles voxelised, over the scene's whole simulated time.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let file: slicelight::scene::SceneFile = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let Some((k, v)) = file.volume.iter().enumerate().find(|(_, v)| v.smoke.is_some()) else { continue };
        let s = v.smoke.clone().unwrap();
        // The scene without the smoke: its objects, to voxelise.
        let mut bare = file.clone();
        bare.volume[k].smoke = None;
        bare.volume[k].metaballs = vec![[v.min[0], v.min[1], v.min[2], 0.1, 0.0]];
        let data = slicelight::scene::build(&bare, &dir).unwrap();
        let (lo, hi) = (Vec3::from(v.min), Vec3::from(v.max));
        let c = smoke::configure("volume", &s, lo, hi).unwrap();
        let cells = smoke::voxelise(&data, &c.params, lo);
        let solid = cells.iter().filter(|&&c| c == 0).count();
        let mut f = c.start(cells);
        let steps = c.steps_to(s.seconds as f64);
        let (mut worst, mut iterations) = (0.0f64, 0u32);
        for _ in 0..steps {
            f.step();
            assert!(f.last.solve.converged, "{}: step {}: {:?}", path.display(), f.params.step, f.last);
            worst = worst.max(f.last.divergence);
            iterations = iterations.max(f.last.solve.iterations);
        }
        println!(
            "{}: {steps} steps, {solid} solid cells, worst relative divergence {worst:.2e}, at most {iterations} iterations, {} puffs",
            path.display(),
            f.puffs.len()
        );
        assert!(worst <= 1e-5, "{}: {worst}", path.display());
        assert!(solid > 0 && !f.puffs.is_empty());
        checked += 1;
    }
    assert!(checked > 0, "no smoke scene in {}", dir.display());
}

#[test]
fn a_state_saved_to_disk_continues_bit_for_bit() {
    // What a second machine or a resumed render does: read the state at
    // step 10 and step on; the same bits as the uninterrupted run.
    let body = "cells = [12, 12, 12]\nturbulence = 2.0\n[[source]]\nposition = [0.6, 0.2, 0.6]\nradius = 0.2\nrate = 10.0\ntemperature = 500.0";
    let c = config(body, Vec3::ZERO, Vec3::splat(1.2));
    let cells = vec![1u32; 12 * 12 * 12];
    let mut run = c.start(cells.clone());
    for _ in 0..10 {
        run.step();
    }
    let dir = tempfile::tempdir().unwrap();
    let hash = smoke::cache::key_hash("test configuration");
    smoke::cache::save(dir.path(), hash, &run).unwrap();
    let mut restarted = smoke::cache::load(dir.path(), hash, 15, &c, &cells).expect("the saved state");
    assert!(smoke::cache::load(dir.path(), hash, 9, &c, &cells).is_none(), "a state after the time asked for");
    assert!(smoke::cache::load(dir.path(), hash ^ 1, 15, &c, &cells).is_none(), "another configuration's state");
    for _ in 0..5 {
        run.step();
        restarted.step();
    }
    assert_eq!(restarted.params.step, 15);
    assert_eq!((&restarted.u, &restarted.temperature, &restarted.smoke), (&run.u, &run.temperature, &run.smoke));
    assert_eq!(restarted.puffs, run.puffs);
    // A damaged file is skipped, not trusted.
    let path = std::fs::read_dir(dir.path()).unwrap().next().unwrap().unwrap().path();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    assert!(smoke::cache::load(dir.path(), hash, 15, &c, &cells).is_none());
}

#[test]
fn render_density_puts_the_fluids_smoke_field_in_the_volume() {
    // `render = "density"`: the volume's grid is the fluid's smoke density
    // at the cell centres, the same numbers the simulation holds.
    let scene = r#"
[camera]
position = [1.0, 1.0, 5.0]
look_at = [1.0, 1.0, 0.0]
vfov_deg = 45.0
resolution = [8, 6]

[[volume]]
min = [0.0, 0.0, -1.0]
max = [2.0, 2.0, 1.0]
sigma_s = [3.0, 3.0, 3.0]
sigma_t = [4.0, 4.0, 4.0]

[volume.smoke]
cells = [8, 8, 8]
seconds = 0.5
dt = 0.1
render = "density"

[[volume.smoke.source]]
position = [1.0, 0.3, 0.0]
radius = 0.3
rate = 10.0
temperature = 500.0
"#;
    let file: slicelight::scene::SceneFile = toml::from_str(scene).unwrap();
    let data = slicelight::scene::build(&file, std::path::Path::new(".")).unwrap();
    let v = &data.volumes.volumes[0];
    let grid = data.volumes.file_grid(v).expect("a grid volume");
    let s = file.volume[0].smoke.clone().unwrap();
    let c = smoke::configure("v", &s, Vec3::from(file.volume[0].min), Vec3::from(file.volume[0].max)).unwrap();
    let mut f = c.start(vec![1; 512]);
    for _ in 0..5 {
        f.step();
    }
    assert_eq!((v.nx, v.ny, v.nz), (8, 8, 8));
    assert_eq!(grid, &f.smoke[..]);
    assert!(grid.iter().any(|&d| d > 0.1), "no smoke in the grid");
}

/// A smoke state file is decoded only if whole: the fuzzer's finding (an
/// array length near 2^64 overflowed the reader's offset) is an error, as
/// is every truncation; the kept corpus file itself decodes.
#[test]
fn a_damaged_state_file_is_an_error_never_a_panic() {
    use slicelight::smoke::{cache, configure, Settings};
    // The small smoke scene's fluid (8^3 cells), as the fuzz target's.
    let scene: toml::Table = toml::from_str(include_str!("data/smoke_small.toml")).expect("the scene");
    let volume = &scene["volume"][0];
    let settings: Settings = volume["smoke"].clone().try_into().expect("settings");
    let corner = |k: &str| -> glam::Vec3 { volume[k].clone().try_into::<[f32; 3]>().expect("a corner").into() };
    let config = configure("volume[0]", &settings, corner("min"), corner("max")).expect("a valid fluid");
    let cells = vec![1u32; config.params.cells as usize];
    let bytes = std::fs::read("../fuzz/corpus/cache/smoke.state").expect("the kept state");
    let hash = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes"));
    cache::decode(&bytes, hash, &config, &cells).expect("the kept state decodes");
    // The first array's length (after magic, hash, step and emitted count).
    let mut huge = bytes.clone();
    huge[24..32].copy_from_slice(&(u64::MAX - 3).to_le_bytes());
    assert!(cache::decode(&huge, hash, &config, &cells).is_err());
    for cut in [0, 7, 8, 23, 31, 100, bytes.len() - 1] {
        assert!(cache::decode(&bytes[..cut], hash, &config, &cells).is_err(), "cut at {cut}");
    }
    assert!(cache::decode(&bytes, hash ^ 1, &config, &cells).is_err(), "another configuration's state");
}
