//! Scene objects to kernel geometry: spheres, triangles, one material per
//! object, and the triangles' BVH.

use anyhow::{anyhow, bail, Result};
use glam::{Quat, Vec3, Vec4};
use slicelight_shaders::types::{
    GlassTriangle, GlassVertex, GpuMaterial, GpuSphere, GpuTriangle, MATERIAL_DIFFUSE, MATERIAL_GLASS, NO_OBJECT,
};
use std::borrow::Cow;
use std::path::Path;

use super::schema::{LatheObject, Material, MeshObject, Object, Rotation, TorusObject, TrefoilKnotObject};
use super::validate::{albedo, finite3, invalid, non_negative3, unit3};

/// Everything the objects of a scene become.
#[derive(Default)]
pub struct Objects {
    pub spheres: Vec<GpuSphere>,
    pub triangles: Vec<GpuTriangle>,
    pub materials: Vec<GpuMaterial>,
    /// The glass meshes' vertices (with smooth normals) and triangles; each
    /// glass triangle is also in `triangles`, with `glass` pointing here.
    pub glass_vertices: Vec<GlassVertex>,
    pub glass_triangles: Vec<GlassTriangle>,
    /// Per object, a hash of what its shape is made from, leaving out where
    /// it stands (a sphere's radius and tessellation, not its centre; a
    /// mesh file's bytes and scale, not its translation): the cache key of
    /// a glass object's light transport table.
    pub shape_keys: Vec<u128>,
}

/// A triangle mesh with one normal per vertex (outward).
#[derive(Default)]
pub struct IndexedMesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub indices: Vec<[u32; 3]>,
}

/// Most triangles one procedural object may have.
const MAX_PROCEDURAL_TRIANGLES: u64 = 20_000_000;

/// Validates an object's material: its albedo, or glass's index and absorption.
fn material(field: &str, albedo3: [f32; 3], m: &Option<Material>) -> Result<GpuMaterial> {
    let a = albedo(&format!("{field}.albedo"), albedo3)?;
    Ok(match m {
        None | Some(Material::Diffuse) => {
            GpuMaterial { albedo: a, kind: MATERIAL_DIFFUSE, ior: Vec4::ONE, ..Default::default() }
        }
        Some(Material::Glass { ior, absorption }) => {
            let ior = ior.rgb();
            if !ior.iter().all(|n| n.is_finite() && *n >= 1.0001 && *n <= 4.0) {
                bail!(invalid(
                    &format!("{field}.material.ior"),
                    "an index of refraction in [1.0001, 4], or three of them (r, g, b)",
                    ior
                ));
            }
            GpuMaterial {
                albedo: a,
                kind: MATERIAL_GLASS,
                ior: Vec3::from(ior).extend(1.0),
                absorption: non_negative3(&format!("{field}.material.absorption"), *absorption)?.extend(0.0),
                ..Default::default()
            }
        }
    })
}

/// Validates the `[[object]]`s and converts them; object `i` gets material `i`.
pub fn build(objects: &[Object], base: &Path) -> Result<Objects> {
    let mut out = Objects::default();
    for (i, obj) in objects.iter().enumerate() {
        let field = format!("object[{i}]");
        let id = i as u32;
        let (albedo3, mat, rotation, pivot) = shared_fields(obj);
        let turn = match rotation {
            None => Quat::IDENTITY,
            Some(r) => {
                let axis = unit3(&format!("{field}.rotation.axis"), r.axis)?;
                if !r.deg.is_finite() {
                    bail!(invalid(&format!("{field}.rotation.deg"), "a finite number of degrees", r.deg));
                }
                Quat::from_axis_angle(axis, r.deg.to_radians())
            }
        };
        let m = material(&field, albedo3, mat)?;
        let glass = m.kind == MATERIAL_GLASS;
        out.materials.push(m);
        let mesh = match obj {
            Object::Sphere(s) => {
                let c = finite3(&format!("{field}.center"), s.center)?;
                if !(s.radius.is_finite() && s.radius > 0.0 && s.radius <= crate::scene::validate::MAX_COORDINATE) {
                    bail!(invalid(&format!("{field}.radius"), "a positive number of metres up to 1e7", s.radius));
                }
                if !glass {
                    if s.segments.is_some() {
                        bail!(invalid(
                            &format!("{field}.segments"),
                            "no segments: only a glass sphere is tessellated",
                            s.segments
                        ));
                    }
                    out.spheres.push(GpuSphere {
                        center_radius: c.extend(s.radius),
                        object: id,
                        material: id,
                        _pad: [0; 2],
                    });
                    continue;
                }
                let segments = s.segments.unwrap_or([96, 64]);
                check_segments(&format!("{field}.segments"), segments)?;
                uv_sphere(c, s.radius, segments)
            }
            Object::Box(b) => {
                let lo = finite3(&format!("{field}.min"), b.min)?;
                let hi = finite3(&format!("{field}.max"), b.max)?;
                if lo.cmpge(hi).any() {
                    bail!(invalid(&format!("{field}.max"), "every coordinate above min's", b.max));
                }
                box_mesh(lo, hi)
            }
            Object::Quad(q) => {
                if glass {
                    bail!(invalid(
                        &format!("{field}.material"),
                        "glass only on closed objects (sphere, box, torus, trefoil_knot, lathe, mesh): a quad has no inside",
                        "glass"
                    ));
                }
                let c = finite3(&format!("{field}.center"), q.center)?;
                let u = finite3(&format!("{field}.u"), q.u)?;
                let v = finite3(&format!("{field}.v"), q.v)?;
                if u.cross(v).length() < 1e-12 {
                    bail!(invalid(&format!("{field}.v"), "an edge not parallel to u and both non-zero", q.v));
                }
                let (hu, hv) = (u * 0.5, v * 0.5);
                let n = u.cross(v).normalize();
                IndexedMesh {
                    positions: vec![c - hu - hv, c + hu - hv, c + hu + hv, c - hu + hv],
                    normals: vec![n; 4],
                    indices: vec![[0, 1, 2], [0, 2, 3]],
                }
            }
            Object::Mesh(mesh) => load_mesh(&field, base, mesh)?,
            Object::Torus(t) => torus(&field, t)?,
            Object::TrefoilKnot(k) => trefoil_knot(&field, k)?,
            Object::Lathe(l) => lathe(&field, l)?,
        };
        out.shape_keys.push(shape_key(obj, base));
        push_mesh(&mut out, &mesh, id, glass, turn, pivot);
    }
    Ok(out)
}

/// The fields every object has: albedo, material, rotation, and the point
/// it turns about (its centre; a mesh's origin, moved by `translate`).
fn shared_fields(obj: &Object) -> ([f32; 3], &Option<Material>, Option<Rotation>, Vec3) {
    match obj {
        Object::Sphere(s) => (s.albedo, &s.material, s.rotation, Vec3::from(s.center)),
        Object::Box(b) => (b.albedo, &b.material, b.rotation, (Vec3::from(b.min) + Vec3::from(b.max)) * 0.5),
        Object::Quad(q) => (q.albedo, &q.material, q.rotation, Vec3::from(q.center)),
        Object::Mesh(m) => (m.albedo, &m.material, m.rotation, Vec3::from(m.translate)),
        Object::Torus(t) => (t.albedo, &t.material, t.rotation, Vec3::from(t.center)),
        Object::TrefoilKnot(k) => (k.albedo, &k.material, k.rotation, Vec3::from(k.center)),
        Object::Lathe(l) => (l.albedo, &l.material, l.rotation, Vec3::from(l.center)),
    }
}

/// See `Objects::shape_keys`.
fn shape_key(obj: &Object, base: &Path) -> u128 {
    let text = match obj {
        Object::Sphere(s) => format!("sphere {:?} {:?}", s.radius, s.segments.unwrap_or([96, 64])),
        Object::Box(b) => format!("box {:?}", (Vec3::from(b.max) - Vec3::from(b.min)).to_array()),
        Object::Quad(q) => format!("quad {:?} {:?}", q.u, q.v),
        Object::Torus(t) => format!("torus {:?} {:?} {:?} {:?}", t.axis, t.major_radius, t.minor_radius, t.segments),
        Object::TrefoilKnot(k) => format!("knot {:?} {:?} {:?}", k.scale, k.tube_radius, k.segments),
        Object::Lathe(l) => format!("lathe {:?} {:?} {:?} {:?}", l.axis, l.profile, l.segments, l.sharp_deg),
        Object::Mesh(m) => {
            // Unreadable or not a regular file: `load_mesh` reports it.
            let path = base.join(&m.file);
            let regular = crate::output::regular_file("mesh", &path, crate::output::MAX_DATA_BYTES).is_ok();
            let bytes = if regular { std::fs::read(&path).unwrap_or_default() } else { Vec::new() };
            format!("mesh {:x} {:?}", twox_hash::XxHash3_128::oneshot(&bytes), m.scale)
        }
    };
    twox_hash::XxHash3_128::oneshot(text.as_bytes())
}

/// Appends a diffuse mesh of `albedo` as one more object (a terrain), with
/// the ripple texture `ripples` (`GpuMaterial::ripples`; 0: none).
pub fn push_diffuse(out: &mut Objects, mesh: &IndexedMesh, albedo: Vec4, ripples: u32) {
    let id = out.materials.len() as u32;
    out.materials.push(GpuMaterial { albedo, kind: MATERIAL_DIFFUSE, ior: Vec4::ONE, ripples, ..Default::default() });
    // Not glass: no table, so no cache key.
    out.shape_keys.push(0);
    push_mesh(out, mesh, id, false, Quat::IDENTITY, Vec3::ZERO);
}

/// Appends a mesh's triangles (and, for glass, its vertices and indexed
/// triangles, sharing normals), turned by `turn` about `pivot`.
fn push_mesh(out: &mut Objects, defined: &IndexedMesh, object: u32, glass: bool, turn: Quat, pivot: Vec3) {
    // Not turned: the positions and normals as defined, exactly, not copied.
    let (positions, normals): (Cow<[Vec3]>, Cow<[Vec3]>) = if turn == Quat::IDENTITY {
        (Cow::Borrowed(&defined.positions), Cow::Borrowed(&defined.normals))
    } else {
        (
            defined.positions.iter().map(|p| pivot + turn * (*p - pivot)).collect(),
            defined.normals.iter().map(|n| turn * *n).collect(),
        )
    };
    let first_vertex = out.glass_vertices.len() as u32;
    if glass {
        let channels = if slicelight_shaders::glass::dispersive(&out.materials[object as usize]) { 3 } else { 1 };
        // The object's diagonal as defined (the same however it is turned),
        // in the normals' w: the range of a compressed table's positions
        // around each vertex.
        let (lo, hi) = defined
            .positions
            .iter()
            .fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let diagonal = (hi - lo).length().max(1e-6);
        let mut block = out.glass_vertices.last().map_or(0, |v| v.table_block + v.channels);
        for ((p, n), defined_normal) in positions.iter().zip(normals.iter()).zip(&defined.normals) {
            out.glass_vertices.push(GlassVertex {
                position: p.extend(1.0),
                normal: n.extend(diagonal),
                tangent: (turn * slicelight_shaders::caustics::frame_tangent(*defined_normal)).extend(0.0),
                rotation: Vec4::from(turn),
                object,
                material: object,
                channels,
                table_block: block,
            });
            block += channels;
        }
    }
    for f in &defined.indices {
        let v = f.map(|i| positions[i as usize]);
        let glass_index = if glass {
            out.glass_triangles.push(GlassTriangle { vertices: f.map(|i| first_vertex + i), object });
            out.glass_triangles.len() as u32 - 1
        } else {
            NO_OBJECT
        };
        out.triangles.push(GpuTriangle {
            v0: v[0].extend(1.0),
            v1: v[1].extend(1.0),
            v2: v[2].extend(1.0),
            object,
            material: object,
            glass: glass_index,
            _pad: 0,
        });
    }
}

fn check_segments(field: &str, [nu, nv]: [u32; 2]) -> Result<()> {
    if nu < 3 || nv < 3 || 2 * nu as u64 * nv as u64 > MAX_PROCEDURAL_TRIANGLES {
        bail!(invalid(
            field,
            &format!("two counts of at least 3 with at most {MAX_PROCEDURAL_TRIANGLES} triangles in all"),
            [nu, nv]
        ));
    }
    Ok(())
}

/// A closed `nu x nv` grid of quads (wrapping in both directions) from a
/// parametrisation giving each grid point's position and outward normal.
fn wrapped_grid(nu: u32, nv: u32, point: impl Fn(u32, u32) -> (Vec3, Vec3)) -> IndexedMesh {
    let mut mesh = IndexedMesh::default();
    for i in 0..nu {
        for j in 0..nv {
            let (p, n) = point(i, j);
            mesh.positions.push(p);
            mesh.normals.push(n);
        }
    }
    let at = |i: u32, j: u32| (i % nu) * nv + (j % nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            mesh.indices.push([a, b, c]);
            mesh.indices.push([a, c, d]);
        }
    }
    mesh
}

/// A UV sphere: `nu` meridians, `nv` bands from pole to pole, analytic normals.
fn uv_sphere(c: Vec3, r: f32, [nu, nv]: [u32; 2]) -> IndexedMesh {
    let mut mesh = IndexedMesh::default();
    let pi = std::f32::consts::PI;
    mesh.positions.push(c + Vec3::Y * r);
    mesh.normals.push(Vec3::Y);
    for j in 1..nv {
        let polar = pi * j as f32 / nv as f32;
        for i in 0..nu {
            let az = std::f32::consts::TAU * i as f32 / nu as f32;
            let n = Vec3::new(polar.sin() * az.cos(), polar.cos(), polar.sin() * az.sin());
            mesh.positions.push(c + n * r);
            mesh.normals.push(n);
        }
    }
    mesh.positions.push(c - Vec3::Y * r);
    mesh.normals.push(Vec3::NEG_Y);
    let south = mesh.positions.len() as u32 - 1;
    let ring = |j: u32, i: u32| 1 + (j - 1) * nu + (i % nu);
    for i in 0..nu {
        mesh.indices.push([0, ring(1, i + 1), ring(1, i)]);
        for j in 1..nv - 1 {
            mesh.indices.push([ring(j, i), ring(j, i + 1), ring(j + 1, i + 1)]);
            mesh.indices.push([ring(j, i), ring(j + 1, i + 1), ring(j + 1, i)]);
        }
        mesh.indices.push([ring(nv - 1, i), ring(nv - 1, i + 1), south]);
    }
    mesh
}

/// A box: six faces of two triangles, each face its own four vertices
/// (flat normals, sharp edges).
fn box_mesh(lo: Vec3, hi: Vec3) -> IndexedMesh {
    let mut mesh = IndexedMesh::default();
    let c = |x: bool, y: bool, z: bool| {
        Vec3::new(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z })
    };
    let (f, t) = (false, true);
    let faces = [
        ([c(f, f, f), c(f, t, f), c(t, t, f), c(t, f, f)], Vec3::NEG_Z),
        ([c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t)], Vec3::Z),
        ([c(f, f, f), c(f, f, t), c(f, t, t), c(f, t, f)], Vec3::NEG_X),
        ([c(t, f, f), c(t, t, f), c(t, t, t), c(t, f, t)], Vec3::X),
        ([c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t)], Vec3::NEG_Y),
        ([c(f, t, f), c(f, t, t), c(t, t, t), c(t, t, f)], Vec3::Y),
    ];
    for (quad, n) in faces {
        let first = mesh.positions.len() as u32;
        mesh.positions.extend(quad);
        mesh.normals.extend([n; 4]);
        mesh.indices.push([first, first + 1, first + 2]);
        mesh.indices.push([first, first + 2, first + 3]);
    }
    mesh
}

fn torus(field: &str, t: &TorusObject) -> Result<IndexedMesh> {
    let c = finite3(&format!("{field}.center"), t.center)?;
    let axis = unit3(&format!("{field}.axis"), t.axis)?;
    if !(t.major_radius.is_finite() && t.major_radius > 0.0 && t.major_radius <= crate::scene::validate::MAX_COORDINATE)
    {
        bail!(invalid(&format!("{field}.major_radius"), "a positive number of metres up to 1e7", t.major_radius));
    }
    if !(t.minor_radius.is_finite() && t.minor_radius > 0.0 && t.minor_radius < t.major_radius) {
        bail!(invalid(
            &format!("{field}.minor_radius"),
            "a positive number of metres below major_radius",
            t.minor_radius
        ));
    }
    let [nu, nv] = t.segments;
    check_segments(&format!("{field}.segments"), t.segments)?;
    // An orthonormal frame (e1, e2) of the plane normal to the axis.
    let e1 = axis.any_orthonormal_vector();
    let e2 = axis.cross(e1);
    Ok(wrapped_grid(nu, nv, |i, j| {
        let u = std::f32::consts::TAU * i as f32 / nu as f32;
        let v = std::f32::consts::TAU * j as f32 / nv as f32;
        let radial = e1 * u.cos() + e2 * u.sin();
        let n = radial * v.cos() + axis * v.sin();
        (c + radial * t.major_radius + n * t.minor_radius, n)
    }))
}

fn trefoil_knot(field: &str, k: &TrefoilKnotObject) -> Result<IndexedMesh> {
    let c = finite3(&format!("{field}.center"), k.center)?;
    if !(k.scale.is_finite() && k.scale > 0.0 && k.scale <= crate::scene::validate::MAX_COORDINATE) {
        bail!(invalid(&format!("{field}.scale"), "a positive number of metres", k.scale));
    }
    // The strands pass within about 0.9 scale of each other.
    if !(k.tube_radius.is_finite() && k.tube_radius > 0.0 && k.tube_radius < 0.4 * k.scale) {
        bail!(invalid(
            &format!("{field}.tube_radius"),
            "a positive number of metres below 0.4 scale (thicker tubes cross)",
            k.tube_radius
        ));
    }
    check_segments(&format!("{field}.segments"), k.segments)?;
    let [nu, nv] = k.segments;
    // The curve with x, z horizontal and its third coordinate up.
    let world = |x: f32, y: f32, z: f32| Vec3::new(x, z, y);
    Ok(wrapped_grid(nu, nv, |i, j| {
        let t = std::f32::consts::TAU * i as f32 / nu as f32;
        let v = std::f32::consts::TAU * j as f32 / nv as f32;
        let r = world(t.sin() + 2.0 * (2.0 * t).sin(), t.cos() - 2.0 * (2.0 * t).cos(), -(3.0 * t).sin());
        let d1 = world(t.cos() + 4.0 * (2.0 * t).cos(), -t.sin() + 4.0 * (2.0 * t).sin(), -3.0 * (3.0 * t).cos());
        let d2 = world(-t.sin() - 8.0 * (2.0 * t).sin(), -t.cos() + 8.0 * (2.0 * t).cos(), 9.0 * (3.0 * t).sin());
        // The Frenet frame: periodic along a closed curve, so the tube closes.
        let tangent = d1.normalize();
        let normal = (d2 - tangent * d2.dot(tangent)).normalize();
        let binormal = tangent.cross(normal);
        let n = normal * v.cos() + binormal * v.sin();
        (c + r * k.scale + n * k.tube_radius, n)
    }))
}

fn lathe(field: &str, l: &LatheObject) -> Result<IndexedMesh> {
    let c = finite3(&format!("{field}.center"), l.center)?;
    let axis = unit3(&format!("{field}.axis"), l.axis)?;
    let profile_field = format!("{field}.profile");
    let p: Vec<glam::Vec2> = l.profile.iter().map(|&[r, h]| glam::Vec2::new(r, h)).collect();
    let m = p.len();
    let closed_outline =
        "at least 3 finite [r, h] points from the axis back to it: first and last r = 0, the others > 0";
    if m < 3
        || p.iter().any(|q| !q.is_finite())
        || p[0].x != 0.0
        || p[m - 1].x != 0.0
        || p[1..m - 1].iter().any(|q| q.x <= 0.0)
    {
        bail!(invalid(&profile_field, closed_outline, &l.profile));
    }
    if !(3..=1_000_000).contains(&l.segments) || 2 * l.segments as u64 * m as u64 > MAX_PROCEDURAL_TRIANGLES {
        bail!(invalid(
            &format!("{field}.segments"),
            &format!("at least 3 slices, at most {MAX_PROCEDURAL_TRIANGLES} triangles in all"),
            l.segments
        ));
    }
    if !(l.sharp_deg.is_finite() && l.sharp_deg > 0.0) {
        bail!(invalid(&format!("{field}.sharp_deg"), "a positive angle in degrees", l.sharp_deg));
    }
    // Outward in the (r, h) half-plane: the outline must run bottom, side,
    // top (counter-clockwise with the axis closing it).
    let area: f32 = p.windows(2).map(|w| w[0].x * w[1].y - w[1].x * w[0].y).sum();
    if area.is_nan() || area <= 0.0 {
        bail!(invalid(
            &profile_field,
            "an outline that runs from the bottom of the axis outward, up and back (counter-clockwise in r, h)",
            &l.profile
        ));
    }
    // Each piece's outward normal, (dh, -dr) normalised.
    let mut piece_normals = Vec::with_capacity(m - 1);
    for (k, w) in p.windows(2).enumerate() {
        let d = w[1] - w[0];
        if d.length() <= 1e-9 {
            bail!(invalid(&profile_field, "no two successive points the same", l.profile[k + 1]));
        }
        piece_normals.push(glam::Vec2::new(d.y, -d.x).normalize());
    }
    // The outline's rings: each inner point once with the mean normal of
    // its two pieces, or twice (one per piece) at a sharp corner.
    let sharp = l.sharp_deg.to_radians().cos();
    let mut rings: Vec<(glam::Vec2, glam::Vec2, bool)> = Vec::new(); // (point, normal, starts a new strip)
    for k in 1..m - 1 {
        let (a, b) = (piece_normals[k - 1], piece_normals[k]);
        if a.dot(b) < sharp {
            rings.push((p[k], a, false));
            rings.push((p[k], b, true));
        } else {
            rings.push((p[k], (a + b).normalize(), false));
        }
    }
    let e1 = axis.any_orthonormal_vector();
    let e2 = axis.cross(e1);
    let n = l.segments;
    let mut mesh = IndexedMesh::default();
    let at = |q: glam::Vec2, normal: glam::Vec2, phi: f32| {
        let radial = e1 * phi.cos() + e2 * phi.sin();
        (c + radial * q.x + axis * q.y, radial * normal.x + axis * normal.y)
    };
    // The poles, with the first and last pieces' normals (flat there).
    let bottom = 0u32;
    mesh.positions.push(c + axis * p[0].y);
    mesh.normals.push(axis * piece_normals[0].y.signum());
    for &(q, normal, _) in &rings {
        for i in 0..n {
            let (pos, nrm) = at(q, normal, std::f32::consts::TAU * i as f32 / n as f32);
            mesh.positions.push(pos);
            mesh.normals.push(nrm);
        }
    }
    let top = mesh.positions.len() as u32;
    mesh.positions.push(c + axis * p[m - 1].y);
    mesh.normals.push(axis * piece_normals[m - 2].y.signum());
    let ring = |j: usize, i: u32| 1 + j as u32 * n + (i % n);
    for i in 0..n {
        // Counter-clockwise seen from outside.
        mesh.indices.push([bottom, ring(0, i + 1), ring(0, i)]);
        for j in 0..rings.len() - 1 {
            if rings[j + 1].2 {
                continue; // the two rings of a sharp corner: one place, no strip between
            }
            mesh.indices.push([ring(j, i), ring(j, i + 1), ring(j + 1, i + 1)]);
            mesh.indices.push([ring(j, i), ring(j + 1, i + 1), ring(j + 1, i)]);
        }
        let last = rings.len() - 1;
        mesh.indices.push([ring(last, i), ring(last, i + 1), top]);
    }
    Ok(mesh)
}

fn load_mesh(field: &str, base: &Path, m: &MeshObject) -> Result<IndexedMesh> {
    let path = base.join(&m.file);
    crate::output::regular_file(&format!("{field}.file"), &path, crate::output::MAX_DATA_BYTES)?;
    let bytes =
        std::fs::read(&path).map_err(|e| anyhow!("{field}.file: cannot read mesh '{}': {e}", path.display()))?;
    mesh_from_obj(field, &path, &bytes, m.scale, m.translate)
}

/// A mesh from the bytes of an OBJ file (`path` names it in errors; its
/// materials are not read), scaled by `scale` and moved by `translate`.
pub fn mesh_from_obj(field: &str, path: &Path, bytes: &[u8], scale: f32, translate: [f32; 3]) -> Result<IndexedMesh> {
    check_obj_indices(field, path, bytes)?;
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let (models, _) =
        tobj::load_obj_buf(&mut std::io::BufReader::new(bytes), &options, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(|e| anyhow!("{field}.file: cannot read mesh '{}': {e}", path.display()))?;
    let translate = finite3(&format!("{field}.translate"), translate)?;
    if !(scale.is_finite() && scale > 0.0 && scale <= crate::scene::validate::MAX_COORDINATE) {
        return Err(invalid(&format!("{field}.scale"), "a positive number", scale));
    }
    let mut mesh = IndexedMesh::default();
    for model in models {
        let first = mesh.positions.len() as u32;
        let p = &model.mesh.positions;
        let count = p.len() / 3;
        mesh.positions.extend((0..count).map(|i| Vec3::new(p[3 * i], p[3 * i + 1], p[3 * i + 2]) * scale + translate));
        let n = &model.mesh.normals;
        let file_normals = n.len() == p.len();
        for f in model.mesh.indices.as_chunks::<3>().0 {
            mesh.indices.push(f.map(|i| first + i));
        }
        if file_normals {
            mesh.normals
                .extend((0..count).map(|i| Vec3::new(n[3 * i], n[3 * i + 1], n[3 * i + 2]).normalize_or_zero()));
        } else {
            mesh.normals.extend(std::iter::repeat_n(Vec3::ZERO, count));
        }
    }
    if mesh.indices.is_empty() {
        return Err(anyhow!("{field}.file: mesh '{}' has no triangles", path.display()));
    }
    if let Some(v) = mesh.positions.iter().find(|v| !v.is_finite()) {
        return Err(anyhow!("{field}.file: mesh '{}' has a vertex that is not finite: {v}", path.display()));
    }
    // Scaled and moved, every vertex stays where scene coordinates may be
    // (`validate::MAX_COORDINATE`): a file in millimetres given `scale =
    // 1e6` would otherwise overflow the kernels' squared distances.
    let limit = crate::scene::validate::MAX_COORDINATE;
    if let Some(v) = mesh.positions.iter().find(|v| v.abs().max_element() > limit) {
        // The file's own vertex, or what the scale and translation made of it.
        let own = ((*v - translate) / scale).abs().max_element() > limit;
        return Err(anyhow!(
            "{field}.{}: mesh '{}' scaled by {scale} and moved by {translate} puts a vertex at {v}, beyond the {limit:e} m every coordinate is held to",
            if own { "file" } else { "scale" },
            path.display()
        ));
    }
    // Vertices without a normal from the file: the area-weighted mean of
    // their faces' (by winding: counter-clockwise seen from outside).
    let mut sums = vec![Vec3::ZERO; mesh.positions.len()];
    for f in &mesh.indices {
        let [a, b, c] = f.map(|i| mesh.positions[i as usize]);
        let n = (b - a).cross(c - a);
        for i in f {
            sums[*i as usize] += n;
        }
    }
    for (n, s) in mesh.normals.iter_mut().zip(sums) {
        if *n == Vec3::ZERO {
            *n = s.normalize_or(Vec3::Y);
        }
    }
    Ok(mesh)
}

/// Every index of a face, line or point names a vertex, texture coordinate
/// or normal defined before it (`1..=n` counting from the first, `-n..=-1`
/// back from the last). tobj turns an index beyond them into an overflowing
/// `usize` (found by fuzzing: `f 2//-4` with no normals), so they are
/// refused here with the line.
fn check_obj_indices(field: &str, path: &Path, bytes: &[u8]) -> Result<()> {
    let text = String::from_utf8_lossy(bytes);
    let mut counts = [0i64; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f" | "l" | "p") => {
                for word in words {
                    for (k, part) in word.split('/').enumerate().take(3) {
                        let Ok(i) = part.parse::<i64>() else { continue };
                        let count = counts[k];
                        if !((1..=count).contains(&i) || (-count..=-1).contains(&i)) {
                            let what = ["vertex", "texture coordinate", "normal"][k];
                            bail!(
                                "{field}.file: mesh '{}', line {}: a {what} index {i}, but {count} are defined before it",
                                path.display(),
                                n + 1
                            );
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Axis-aligned bounds of all geometry (spheres and triangles).
pub fn bounds(spheres: &[GpuSphere], tris: &[GpuTriangle]) -> Option<(Vec3, Vec3)> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for s in spheres {
        let c = s.center_radius.truncate();
        lo = lo.min(c - s.center_radius.w);
        hi = hi.max(c + s.center_radius.w);
    }
    for t in tris {
        for v in [t.v0, t.v1, t.v2] {
            lo = lo.min(v.truncate());
            hi = hi.max(v.truncate());
        }
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::schema::LatheObject;
    use std::collections::HashMap;

    fn lathe_of(profile: &[[f32; 2]]) -> Result<IndexedMesh> {
        let l = LatheObject {
            center: [0.0, 0.0, 0.0],
            axis: [0.2, 1.0, 0.1],
            profile: profile.to_vec(),
            segments: 24,
            sharp_deg: 40.0,
            albedo: [0.8; 3],
            material: None,
            rotation: None,
        };
        lathe("object[0]", &l)
    }

    #[test]
    fn a_lathe_is_closed_and_faces_outward() {
        // A cup: a flat foot, a stem, a hollow bowl (sharp corners and a
        // concave inside).
        let cup = [
            [0.0, 0.0],
            [0.3, 0.0],
            [0.3, 0.05],
            [0.05, 0.1],
            [0.05, 0.4],
            [0.3, 0.6],
            [0.3, 0.9],
            [0.27, 0.9],
            [0.27, 0.62],
            [0.0, 0.45],
        ];
        let mesh = lathe_of(&cup).unwrap();
        // Closed: every edge (by position) belongs to exactly two triangles,
        // once each way.
        let key = |p: Vec3| p.to_array().map(|x| (x * 1e5).round() as i64);
        let mut edges: HashMap<_, i32> = HashMap::new();
        for f in &mesh.indices {
            for k in 0..3 {
                let (a, b) = (key(mesh.positions[f[k] as usize]), key(mesh.positions[f[(k + 1) % 3] as usize]));
                *edges.entry((a, b)).or_default() += 1;
                *edges.entry((b, a)).or_default() -= 1;
            }
        }
        assert!(edges.values().all(|&n| n == 0), "open or inconsistently wound edges");
        // Outward: each face's winding agrees with its vertices' normals,
        // and the volume by the divergence theorem is positive.
        let mut volume = 0.0;
        for f in &mesh.indices {
            let [a, b, c] = f.map(|i| mesh.positions[i as usize]);
            let n = (b - a).cross(c - a);
            let mean = f.iter().map(|&i| mesh.normals[i as usize]).sum::<Vec3>();
            assert!(n.dot(mean) > 0.0, "face {f:?} wound against its normals");
            volume += a.dot(b.cross(c)) / 6.0;
        }
        assert!(volume > 0.0, "volume {volume}");
    }

    #[test]
    fn a_bad_lathe_outline_names_the_field() {
        for bad in [
            vec![[0.1, 0.0], [0.3, 0.5], [0.0, 1.0]], // does not start on the axis
            vec![[0.0, 0.0], [0.3, 0.5]],             // too short
            vec![[0.0, 1.0], [0.3, 0.5], [0.0, 0.0]], // clockwise
            vec![[0.0, 0.0], [0.3, 0.0], [0.3, 0.0], [0.0, 1.0]], // a repeated point
        ] {
            let e = lathe_of(&bad).err().expect("refused").to_string();
            assert!(e.contains("object[0].profile"), "{e}");
        }
    }
}
