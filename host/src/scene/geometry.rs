//! Scene objects to kernel geometry: spheres, triangles, one material per
//! object, and the triangles' BVH.

use anyhow::{anyhow, bail, Result};
use glam::Vec3;
use slicelight_shaders::types::{GpuMaterial, GpuSphere, GpuTriangle, MATERIAL_DIFFUSE};
use std::path::Path;

use super::schema::{MeshObject, Object, TorusObject};
use super::validate::{albedo, finite3, invalid, unit3};

/// Everything the objects of a scene become.
#[derive(Default)]
pub struct Objects {
    pub spheres: Vec<GpuSphere>,
    pub triangles: Vec<GpuTriangle>,
    pub materials: Vec<GpuMaterial>,
}

/// Validates the `[[object]]`s and converts them; object `i` gets material `i`.
pub fn build(objects: &[Object], base: &Path) -> Result<Objects> {
    let mut out = Objects::default();
    for (i, obj) in objects.iter().enumerate() {
        let field = format!("object[{i}]");
        let id = i as u32;
        let material = |a: [f32; 3]| -> Result<GpuMaterial> {
            Ok(GpuMaterial { albedo: albedo(&format!("{field}.albedo"), a)?, kind: MATERIAL_DIFFUSE, _pad: [0; 3] })
        };
        match obj {
            Object::Sphere(s) => {
                let c = finite3(&format!("{field}.center"), s.center)?;
                if !(s.radius.is_finite() && s.radius > 0.0) {
                    bail!(invalid(&format!("{field}.radius"), "a positive number of metres", s.radius));
                }
                out.materials.push(material(s.albedo)?);
                out.spheres.push(GpuSphere {
                    center_radius: c.extend(s.radius),
                    object: id,
                    material: id,
                    _pad: [0; 2],
                });
            }
            Object::Box(b) => {
                let lo = finite3(&format!("{field}.min"), b.min)?;
                let hi = finite3(&format!("{field}.max"), b.max)?;
                if lo.cmpge(hi).any() {
                    bail!(invalid(&format!("{field}.max"), "every coordinate above min's", b.max));
                }
                out.materials.push(material(b.albedo)?);
                push_box(&mut out.triangles, lo, hi, id);
            }
            Object::Quad(q) => {
                let c = finite3(&format!("{field}.center"), q.center)?;
                let u = finite3(&format!("{field}.u"), q.u)?;
                let v = finite3(&format!("{field}.v"), q.v)?;
                if u.cross(v).length() < 1e-12 {
                    bail!(invalid(&format!("{field}.v"), "an edge not parallel to u and both non-zero", q.v));
                }
                out.materials.push(material(q.albedo)?);
                let (hu, hv) = (u * 0.5, v * 0.5);
                push_quad(&mut out.triangles, [c - hu - hv, c + hu - hv, c + hu + hv, c - hu + hv], id);
            }
            Object::Mesh(mesh) => {
                out.materials.push(material(mesh.albedo)?);
                load_mesh(&field, base, mesh, id, &mut out.triangles)?;
            }
            Object::Torus(t) => {
                out.materials.push(material(t.albedo)?);
                push_torus(&field, t, id, &mut out.triangles)?;
            }
        }
    }
    Ok(out)
}

fn triangle(v: [Vec3; 3], object: u32) -> GpuTriangle {
    GpuTriangle {
        v0: v[0].extend(1.0),
        v1: v[1].extend(1.0),
        v2: v[2].extend(1.0),
        object,
        material: object,
        _pad: [0; 2],
    }
}

fn push_quad(tris: &mut Vec<GpuTriangle>, [a, b, c, d]: [Vec3; 4], object: u32) {
    tris.push(triangle([a, b, c], object));
    tris.push(triangle([a, c, d], object));
}

fn push_box(tris: &mut Vec<GpuTriangle>, lo: Vec3, hi: Vec3, object: u32) {
    let c = |x: bool, y: bool, z: bool| {
        Vec3::new(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z })
    };
    let (f, t) = (false, true);
    push_quad(tris, [c(f, f, f), c(t, f, f), c(t, t, f), c(f, t, f)], object);
    push_quad(tris, [c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t)], object);
    push_quad(tris, [c(f, f, f), c(f, t, f), c(f, t, t), c(f, f, t)], object);
    push_quad(tris, [c(t, f, f), c(t, t, f), c(t, t, t), c(t, f, t)], object);
    push_quad(tris, [c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t)], object);
    push_quad(tris, [c(f, t, f), c(t, t, f), c(t, t, t), c(f, t, t)], object);
}

/// Most triangles one procedural object may have.
const MAX_PROCEDURAL_TRIANGLES: u64 = 20_000_000;

fn push_torus(field: &str, t: &TorusObject, object: u32, tris: &mut Vec<GpuTriangle>) -> Result<()> {
    let c = finite3(&format!("{field}.center"), t.center)?;
    let axis = unit3(&format!("{field}.axis"), t.axis)?;
    if !(t.major_radius.is_finite() && t.major_radius > 0.0) {
        bail!(invalid(&format!("{field}.major_radius"), "a positive number of metres", t.major_radius));
    }
    if !(t.minor_radius.is_finite() && t.minor_radius > 0.0 && t.minor_radius < t.major_radius) {
        bail!(invalid(
            &format!("{field}.minor_radius"),
            "a positive number of metres below major_radius",
            t.minor_radius
        ));
    }
    let [nu, nv] = t.segments;
    if nu < 3 || nv < 3 || 2 * nu as u64 * nv as u64 > MAX_PROCEDURAL_TRIANGLES {
        bail!(invalid(
            &format!("{field}.segments"),
            &format!("two counts of at least 3 with at most {MAX_PROCEDURAL_TRIANGLES} triangles in all"),
            t.segments
        ));
    }
    // An orthonormal frame (e1, e2) of the plane normal to the axis.
    let e1 = axis.any_orthonormal_vector();
    let e2 = axis.cross(e1);
    let point = |i: u32, j: u32| {
        let u = std::f32::consts::TAU * (i % nu) as f32 / nu as f32;
        let v = std::f32::consts::TAU * (j % nv) as f32 / nv as f32;
        let radial = e1 * u.cos() + e2 * u.sin();
        c + radial * (t.major_radius + t.minor_radius * v.cos()) + axis * (t.minor_radius * v.sin())
    };
    for i in 0..nu {
        for j in 0..nv {
            push_quad(tris, [point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1)], object);
        }
    }
    Ok(())
}

fn load_mesh(field: &str, base: &Path, m: &MeshObject, object: u32, tris: &mut Vec<GpuTriangle>) -> Result<()> {
    let path = base.join(&m.file);
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let (models, _) = tobj::load_obj(&path, &options)
        .map_err(|e| anyhow!("{field}.file: cannot read mesh '{}': {e}", path.display()))?;
    let translate = finite3(&format!("{field}.translate"), m.translate)?;
    if !(m.scale.is_finite() && m.scale > 0.0) {
        return Err(invalid(&format!("{field}.scale"), "a positive number", m.scale));
    }
    let before = tris.len();
    for model in models {
        let p = &model.mesh.positions;
        let vertex =
            |i: u32| Vec3::new(p[3 * i as usize], p[3 * i as usize + 1], p[3 * i as usize + 2]) * m.scale + translate;
        for f in model.mesh.indices.as_chunks::<3>().0 {
            tris.push(triangle([vertex(f[0]), vertex(f[1]), vertex(f[2])], object));
        }
    }
    if tris.len() == before {
        return Err(anyhow!("{field}.file: mesh '{}' has no triangles", path.display()));
    }
    if let Some(t) = tris[before..].iter().find(|t| !(t.v0.is_finite() && t.v1.is_finite() && t.v2.is_finite())) {
        return Err(anyhow!("{field}.file: mesh '{}' has a vertex that is not finite: {t:?}", path.display()));
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
