//! The pass registry, checked against the compiled kernels: bindings as the
//! SPIR-V declares them, one resource per binding, the scatter primitive's
//! closed form on the CPU, the BVH's cost, antialiasing and layered EXR.

mod common;

use glam::{Vec3, Vec4};
use indicatif::ProgressBar;
use slicelight::passes::{Frame, Pass, PASSES};
use slicelight::render::{self, Backend};
use std::collections::{BTreeMap, BTreeSet};

/// For every entry point of the SPIR-V module: the bindings its body uses,
/// and whether it writes each, as naga (wgpu's own SPIR-V reader) sees them.
fn declared_bindings() -> BTreeMap<String, BTreeMap<u32, bool>> {
    let module =
        naga::front::spv::parse_u8_slice(slicelight::gpu::SPIRV, &Default::default()).expect("the kernels parse");
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .expect("the kernels validate");
    let mut out = BTreeMap::new();
    for (k, ep) in module.entry_points.iter().enumerate() {
        let fi = info.get_entry_point(k);
        let mut used = BTreeMap::new();
        for (handle, var) in module.global_variables.iter() {
            let usage = fi[handle];
            if usage.is_empty() {
                continue;
            }
            // naga's SPIR-V reader keeps the invocation-id inputs as private
            // globals without a binding; only resources have one.
            let Some(binding) = var.binding.as_ref() else {
                assert!(
                    !matches!(var.space, naga::AddressSpace::Storage { .. }),
                    "{}: a storage buffer without a binding",
                    ep.name
                );
                continue;
            };
            assert_eq!(binding.group, 0, "{}: binding {} in group {}", ep.name, binding.binding, binding.group);
            let writes = match var.space {
                naga::AddressSpace::Storage { access } => access.contains(naga::StorageAccess::STORE),
                other => panic!("{}: binding {} in {other:?}, expected a storage buffer", ep.name, binding.binding),
            };
            used.insert(binding.binding, writes);
        }
        out.insert(ep.name.clone(), used);
    }
    out
}

#[test]
fn every_pass_binds_what_its_kernel_declares() {
    let declared = declared_bindings();
    for pass in PASSES.iter() {
        let kernel =
            declared.get(pass.kernel()).unwrap_or_else(|| panic!("{}: no entry point {}", pass.name(), pass.kernel()));
        let mut host = BTreeMap::new();
        for r in pass.reads() {
            host.insert(r.binding, false);
        }
        for r in pass.writes() {
            assert!(host.insert(r.binding, true).is_none(), "{}: {} both read and written", pass.name(), r.name);
        }
        assert_eq!(&host, kernel, "{}: host bindings (binding -> written) differ from the SPIR-V's", pass.name());
        // A variant compiles some code out, so it may use fewer of the
        // pass's bindings, but none it does not declare, and writes the same.
        for variant in pass.variants() {
            let used = declared.get(*variant).unwrap_or_else(|| panic!("{}: no entry point {variant}", pass.name()));
            for (binding, writes) in used {
                assert_eq!(
                    host.get(binding),
                    Some(writes),
                    "{variant}: binding {binding} not as {} declares it",
                    pass.name()
                );
            }
            assert!(!used.is_empty(), "{variant} binds nothing");
        }
    }
    // Every entry point belongs to a registered pass or to a family's own kernels.
    let own: Vec<_> = slicelight::passes::families().iter().flat_map(|f| f.kernels.iter()).collect();
    let kernels: BTreeSet<_> = PASSES
        .iter()
        .flat_map(|p| std::iter::once(p.kernel()).chain(p.variants().iter().copied()))
        .chain(own.iter().map(|k| k.name))
        .collect();
    for name in declared.keys() {
        assert!(kernels.contains(name.as_str()), "entry point {name} is not registered as a pass or a family's kernel");
    }
}

/// A family's own kernels (a simulation's step, dispatched outside the
/// frame's passes) bind exactly what their SPIR-V declares, and their
/// bindings name no frame resource.
#[test]
fn every_family_kernel_binds_what_its_entry_point_declares() {
    let declared = declared_bindings();
    let frame: BTreeSet<u32> =
        PASSES.iter().flat_map(|p| p.reads().iter().chain(p.writes())).map(|r| r.binding).collect();
    let mut count = 0;
    for family in slicelight::passes::families() {
        for k in family.kernels {
            let used = declared.get(k.name).unwrap_or_else(|| panic!("{}: no entry point {}", family.name, k.name));
            let mut host = BTreeMap::new();
            for b in k.reads {
                host.insert(*b, false);
            }
            for b in k.writes {
                assert!(host.insert(*b, true).is_none(), "{}: binding {b} both read and written", k.name);
            }
            assert_eq!(&host, used, "{}: host bindings (binding -> written) differ from the SPIR-V's", k.name);
            for b in host.keys() {
                assert!(!frame.contains(b), "{}: binding {b} is also a frame resource's", k.name);
            }
            count += 1;
        }
    }
    assert!(count >= 20, "the fluid's kernels are registered ({count} found)");
}

#[test]
fn every_binding_is_one_resource_and_every_pass_one_name() {
    let mut by_binding = BTreeMap::new();
    for pass in PASSES.iter() {
        for r in pass.reads().iter().chain(pass.writes()) {
            let name = by_binding.entry(r.binding).or_insert(r.name);
            assert_eq!(*name, r.name, "binding {} is both {name} and {}", r.binding, r.name);
        }
    }
    let names: BTreeSet<_> = PASSES.iter().map(|p| p.name()).collect();
    assert_eq!(names.len(), PASSES.len(), "two passes share a name");
}

#[test]
fn scatter_accumulation_is_exact_and_order_independent_on_the_cpu() {
    // 1.8 M invocations into 4 bins on every rayon thread: the closed form,
    // saturation instead of wrapping, and the same words twice.
    let pass = slicelight::passes::by_name("scatter_check").unwrap();
    let data = common::scene_from_str(&torus_scene([8, 4]));
    let mut words = Vec::new();
    for _ in 0..2 {
        let mut frame = Frame::default();
        pass.run_cpu(&data, &data.common, &mut frame, &ProgressBar::hidden());
        // A wrong sum is an error (the render fails), not a line in the stats.
        let report = pass.report(&data, &frame).expect("the closed form holds").expect("a verdict");
        println!("{report}");
        words.push(frame.get::<u32>(&slicelight::common::scatter_check::CHECK_WORDS).to_vec());
    }
    assert_eq!(words[0], words[1]);
}

fn torus_scene(segments: [u32; 2]) -> String {
    format!(
        r#"
        [camera]
        position = [0.0, 3.0, 6.0]
        look_at = [0.0, 0.0, 0.0]
        vfov_deg = 45.0
        resolution = [64, 48]
        [[spotlight]]
        position = [0.0, 5.0, 0.0]
        direction = [0.0, -1.0, 0.0]
        cutoff_deg = 40.0
        intensity = [10.0, 10.0, 10.0]
        [[object]]
        type = "torus"
        center = [0.0, 0.0, 0.0]
        major_radius = 1.5
        minor_radius = 0.5
        segments = [{}, {}]
        [[object]]
        type = "quad"
        center = [0.0, -0.5, 0.0]
        u = [8.0, 0.0, 0.0]
        v = [0.0, 0.0, 8.0]
    "#,
        segments[0], segments[1]
    )
}

#[test]
fn bvh_cost_grows_about_logarithmically_with_triangles() {
    // The same torus at 1 k, 10 k and 100 k triangles: the mean number of
    // BVH nodes a view ray visits (the kernels' own count). Linear growth
    // would multiply it by 10 per step; a BVH adds a few levels per step.
    let mut means = Vec::new();
    for segments in [[32, 16], [100, 50], [316, 158]] {
        let data = common::scene_from_str(&torus_scene(segments));
        let geometry = data.geometry();
        let (mut visits, mut rays) = (0u64, 0u64);
        for y in 0..data.height() {
            for x in 0..data.width() {
                let (o, d) = slicelight::shaders::camera::camera_ray(&data.common, x, y);
                visits += slicelight::shaders::geometry::trace_nearest(o, d, 0.0, f32::MAX, &geometry).visits as u64;
                rays += 1;
            }
        }
        let mean = visits as f64 / rays as f64;
        println!(
            "{} triangles: {} nodes, depth {}, {mean:.1} node visits per ray",
            data.triangles.len(),
            data.bvh_nodes.len(),
            slicelight::bvh::depth(&data.bvh_nodes)
        );
        means.push((data.triangles.len(), mean));
    }
    // 100x the triangles: at most 3x the visits (measured: see the output).
    assert!(means[2].1 < 3.0 * means[0].1, "{means:?}");
}

#[test]
fn bvh_finds_the_same_nearest_hit_as_testing_every_triangle() {
    let data = common::scene_from_str(&torus_scene([60, 30]));
    let geometry = data.geometry();
    let mut state = 99u64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 40) as f32) / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    for _ in 0..20_000 {
        let o = Vec3::new(next(), next(), next()) * 4.0;
        let d = (Vec3::new(next(), next(), next()) * 2.0 - o * 0.3).normalize();
        let hit = slicelight::shaders::geometry::trace_nearest(o, d, 0.0, f32::MAX, &geometry);
        let brute = data
            .triangles
            .iter()
            .map(|t| {
                slicelight::shaders::geometry::ray_triangle(
                    o,
                    d,
                    t.v0.truncate(),
                    t.v1.truncate(),
                    t.v2.truncate(),
                    0.0,
                )
            })
            .fold(f32::MAX, f32::min);
        assert_eq!(hit.distance, brute, "ray {o} {d}");
    }
}

#[test]
fn rays_through_a_fine_meshs_edges_and_vertices_do_not_slip_through() {
    // torus_100k's mesh (triangles about 2.5 cm across) seen from its
    // camera 8 m away: rays aimed exactly at shared edges' midpoints and at
    // vertices must stop at the near surface, not pass between the
    // triangles there to the far side of the torus (one pixel of
    // torus_100k did, 140 levels off the reference, when the edge tolerance
    // was a fixed 1e-6 of a triangle: rounding at 8 m is ~1e-6 m, 4e-5 of
    // these triangles).
    let data = slicelight::scene::load(&common::root().join("scenes/torus_100k.toml")).unwrap();
    let geometry = data.geometry();
    let o = data.common.camera_position.truncate();
    let (mut checked, mut slipped) = (0, 0);
    for t in data.triangles.iter().step_by(7) {
        let (v0, v1, v2) = (t.v0.truncate(), t.v1.truncate(), t.v2.truncate());
        let normal = (v1 - v0).cross(v2 - v0);
        for target in [(v0 + v1) * 0.5, (v1 + v2) * 0.5, (v2 + v0) * 0.5, v0] {
            let d = (target - o).normalize();
            // The target is on the mesh, so the nearest hit is at most as
            // far (nearer where other parts hide it); rays grazing the
            // triangle are left out.
            if normal.dot(d).abs() < 0.2 * normal.length() {
                continue;
            }
            let hit = slicelight::shaders::geometry::trace_nearest(o, d, 0.0, f32::MAX, &geometry);
            let aimed = (target - o).length();
            checked += 1;
            if hit.distance > aimed * (1.0 + 1e-5) {
                slipped += 1;
            }
        }
    }
    assert!(checked > 20_000, "{checked}");
    assert_eq!(slipped, 0, "{slipped} of {checked} rays slipped through");
}

#[test]
fn antialiasing_averages_the_sub_pixel_samples() {
    // With 4 samples, each pixel is the mean of four renders at the 2x2
    // grid positions: render the four on their own (a 1-sample render at a
    // set sample index) and compare.
    let mut data = common::scene_from_str(&torus_scene([48, 24]));
    data = data.reconfigure(move |f| f.camera.samples_per_pixel = 4).unwrap();
    let (aa, stats) = render::render(&data, &Backend::Cpu, false).unwrap();
    assert_eq!(stats.samples_per_pixel, 4);
    let mut mean = vec![Vec4::ZERO; aa.len()];
    let pb = ProgressBar::hidden();
    for s in 0..4 {
        let mut common = data.common;
        common.sample_index = s;
        let mut frame = Frame::default();
        for &pass in PASSES.iter().filter(|p| p.plan(&data).runs) {
            pass.run_cpu(&data, &common, &mut frame, &pb);
        }
        for &pass in PASSES.iter().filter(|p| p.plan(&data).runs) {
            if let Some(layer) = pass.radiance_layer() {
                for (m, v) in mean.iter_mut().zip(frame.get::<Vec4>(layer)) {
                    *m += v.truncate().extend(0.0) * 0.25;
                }
            }
        }
    }
    let worst = aa.iter().zip(&mean).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max);
    let peak = mean.iter().map(|p| p.max_element()).fold(0.0, f32::max);
    // The same f32 sums in a different order: a few ulps of the peak.
    assert!(worst <= 1e-6 * peak, "worst {worst} of peak {peak}");
    // And the samples differ: on the torus's silhouette the average is
    // neither sample (the antialiasing does something).
    let (one, _) = {
        let mut d1 = data.clone();
        d1 = d1.reconfigure(move |f| f.camera.samples_per_pixel = 1).unwrap();
        render::render(&d1, &Backend::Cpu, false).unwrap()
    };
    let changed = one.iter().zip(&aa).filter(|(a, b)| (**a - **b).abs().max_element() > 1e-3 * peak).count();
    assert!(changed > 20, "only {changed} pixels changed with 4 samples");
}

#[test]
fn layered_exr_holds_each_pass_and_reads_back_as_the_beauty_image() {
    let data = common::scene_from_str(
        &torus_scene([48, 24])
            .replace("[camera]", "[medium]\nsigma_s = [0.05, 0.05, 0.05]\nsigma_t = [0.06, 0.06, 0.06]\n[camera]"),
    );
    let r = render::render_layers(&data, &Backend::Cpu, false).unwrap();
    let names: Vec<_> = r.layers.iter().map(|(n, _)| *n).collect();
    assert_eq!(names, ["surface", "shafts"]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("layers.exr");
    slicelight::output::write_layered(&path, &r.image, &r.layer_slices(), data.width(), data.height(), 1.0).unwrap();
    // The beauty image, as an RGB-only reader sees it.
    let img = image::open(&path).unwrap().to_rgb32f();
    for (p, q) in img.pixels().zip(&r.image) {
        assert_eq!([p[0], p[1], p[2]], [q.x, q.y, q.z]);
    }
    // Every layer's channels, as a layer-aware reader sees them.
    let exr = exr::prelude::read_all_flat_layers_from_file(&path).unwrap();
    let channels: BTreeSet<String> = exr.layer_data[0].channel_data.list.iter().map(|c| c.name.to_string()).collect();
    for c in ["R", "G", "B", "surface.R", "surface.G", "surface.B", "shafts.R", "shafts.G", "shafts.B"] {
        assert!(channels.contains(c), "no channel {c} in {channels:?}");
    }
    // And beauty = surface + shafts.
    let l = r.layer_slices();
    for ((s, f), b) in l[0].1.iter().zip(l[1].1).zip(&r.image) {
        assert!((*s + *f - *b).abs().max_element() <= 1e-6 * b.max_element().max(1e-6));
    }
}

#[test]
fn passes_run_after_what_they_read() {
    // The run order comes from the family list and each family's own order
    // (whole-frame passes first); a resource a pass reads must be written
    // only by passes that run before it, or the pass would read last
    // frame's (or blank) data. Fails if a family is registered out of order.
    let order: Vec<&dyn Pass> = PASSES.iter().copied().collect();
    for (i, pass) in order.iter().enumerate() {
        for r in pass.reads() {
            for (j, writer) in order.iter().enumerate() {
                if j != i && writer.writes().iter().any(|w| w.binding == r.binding) {
                    assert!(j < i, "{} reads {} but {} writes it later", pass.name(), r.name, writer.name());
                }
            }
        }
    }
    // The families' lists hold every pass once.
    let names: BTreeSet<_> = order.iter().map(|p| p.name()).collect();
    assert_eq!(names.len(), order.len());
}

#[test]
fn the_plan_lists_every_registered_pass() {
    let data = common::scene_from_str(&torus_scene([8, 4]));
    let plan = render::plan(&data);
    let names: Vec<_> = plan.iter().map(|p| p.name).collect();
    let registered: Vec<_> = PASSES.iter().map(|p: &&dyn Pass| p.name()).collect();
    assert_eq!(names, registered);
    let check = plan.iter().find(|p| p.name == "scatter_check").unwrap();
    assert!(!check.ran, "the self-check runs only when asked for");
}

#[test]
fn a_dropped_buffers_storage_is_reused_and_zeroed_again() {
    // An unusual size, so that no other test's buffers match it.
    let len = 4 * ((1 << 16) + 7919);
    let mut a = slicelight::passes::Buffer::zeroed::<f32>(len);
    a.as_mut_slice::<f32>().fill(1.0);
    let storage = a.as_slice::<f32>().as_ptr();
    drop(a);
    let b = slicelight::passes::Buffer::zeroed::<f32>(len);
    assert_eq!(b.as_slice::<f32>().as_ptr(), storage, "the kept storage was not reused");
    assert!(b.as_slice::<f32>().iter().all(|&x| x == 0.0), "reused storage not zeroed");
}

#[test]
fn frames_in_one_process_do_not_see_each_others_buffers() {
    // Pass outputs reuse the storage of the previous frame's buffers without
    // zeroing it (`Frame::write_all`): a pixel a kernel failed to write
    // would keep another scene's value. Fig. 6, then the stage (the same
    // size, so its buffers take Fig. 6's storage), then Fig. 6 again: the
    // two Fig. 6 images are the same to the bit.
    let load = |name: &str| slicelight::scene::load(&common::root().join(format!("scenes/{name}.toml"))).unwrap();
    let (fig6, stage) = (load("fig6_sphere"), load("fig7_stage"));
    let first = render::render_layers(&fig6, &Backend::Cpu, false).unwrap();
    let first_image = first.image.clone();
    drop(first);
    let other = render::render(&stage, &Backend::Cpu, false).unwrap().0;
    assert_ne!(other, first_image);
    let again = render::render(&fig6, &Backend::Cpu, false).unwrap().0;
    assert!(again == first_image, "Fig. 6 rendered differently after the stage");
}

#[test]
fn every_shipped_scene_goes_to_exactly_one_bench_sweep() {
    // `slicelight bench SCENE` routes a scene to the one family sweep that
    // takes it; two takers or none is an error there, so every shipped
    // scene must have exactly one.
    let sweeps = slicelight::bench::sweeps();
    let dir = common::root().join("scenes");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    assert!(paths.len() > 20, "{} scenes", paths.len());
    for path in paths {
        let data = slicelight::scene::load(&path).unwrap();
        let takers: Vec<&str> = sweeps.iter().filter(|(_, s)| s.takes(&data)).map(|(n, _)| *n).collect();
        assert_eq!(takers.len(), 1, "{}: taken by {takers:?}", path.display());
        // Clouds go to the volumes' sweep, except over the sea (whose
        // sweep measures the water); smoke to the smoke's.
        let smoke = slicelight::smoke::bench::has_smoke(&data);
        if data.volumes.enabled && !data.sea.enabled {
            assert_eq!(takers, [if smoke { "smoke" } else { "volumes" }], "{}", path.display());
        }
    }
}
