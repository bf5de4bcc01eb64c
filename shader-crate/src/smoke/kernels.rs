//! The fluid's entry points: each reads its dispatch's parameters
//! (`FluidDispatch`, binding 100) and the invocation index, calls one of the
//! per-element functions in `smoke` and stores the result. The host
//! (`host/src/smoke/gpu.rs`) binds the arrays a step needs at the generic
//! bindings below (an input `a` may be `u` in one dispatch and the
//! temperature in the next) and runs the step's sequence; the CPU backend
//! calls the same functions (`host/src/smoke/fluid.rs`).
//!
//! Bindings: 100 parameters; 101 to 106 inputs `a` to `f`; 107 to 109 the
//! velocity `u`, `v`, `w`; 110 flags (fluid cells or stencils); 111 points
//! (`Vec4`, cells); 112 and 113 outputs (read-write where a kernel updates
//! in place); 114 points out; 115 partial reductions; 116 and 117 indices
//! and values held fixed (the sources).

// An entry point's parameters are its bindings.
#![allow(clippy::too_many_arguments)]

use super::*;
use crate::glam::{UVec3, Vec4};
use spirv_std::spirv;

/// The invocation's element, or `None` past the dispatch's count.
fn element(id: UVec3, groups: UVec3, d: &FluidDispatch) -> Option<u32> {
    let i = crate::flat_index(id, groups);
    if i < d.count {
        Some(i)
    } else {
        None
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_departure(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 107)] u: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 108)] v: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 109)] w: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 114)] points_out: &mut [Vec4],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        points_out[i as usize] = departure(&d.fluid, d.kind, i, Velocity { u, v, w }).extend(0.0);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_trace(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 107)] u: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 108)] v: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 109)] w: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 111)] points: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 114)] points_out: &mut [Vec4],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        let x = points[i as usize].truncate();
        points_out[i as usize] = trace(&d.fluid, Velocity { u, v, w }, x, d.direction).extend(0.0);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_sample(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 111)] points: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = sample(&d.fluid, d.kind, a, points[i as usize].truncate());
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_advect(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 107)] u: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 108)] v: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 109)] w: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = advect(&d.fluid, d.kind, i, a, Velocity { u, v, w }, d.direction);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_maccormack(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 103)] c: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 111)] points: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = maccormack_from(&d.fluid, d.kind, i, a, b, c, points[i as usize].truncate());
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_advect_centres(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 107)] u: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 108)] v: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 109)] w: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 113)] out2: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        let (t, s) = advect_centres(&d.fluid, i, a, b, Velocity { u, v, w }, d.direction);
        out[i as usize] = t;
        out2[i as usize] = s;
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_sample_centres(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 111)] points: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 113)] out2: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        let x = points[i as usize].truncate();
        out[i as usize] = sample(&d.fluid, KIND_TEMPERATURE, a, x);
        out2[i as usize] = sample(&d.fluid, KIND_SMOKE, b, x);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_maccormack_centres(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] t: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] s: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 103)] t_forward: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 104)] s_forward: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 105)] t_back: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 106)] s_back: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 111)] points: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 113)] out2: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        let t = Stages { q: t, forward: t_forward, back: t_back };
        let s = Stages { q: s, forward: s_forward, back: s_back };
        let (x, y) = maccormack_centres_from(&d.fluid, i, t, s, points[i as usize].truncate());
        out[i as usize] = x;
        out2[i as usize] = y;
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_force(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = force_face(&d.fluid, d.kind, i, out[i as usize], a);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_diffuse(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = diffuse(&d.fluid, d.kind, i, a, b, d.scalar, flags);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_eddy(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] += temperature_eddy(&d.fluid, i);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_hold(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 116)] indices: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 117)] values: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[indices[i as usize] as usize] = values[i as usize];
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_solids(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 113)] out2: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        if flags[i as usize] == 0 {
            out[i as usize] = d.fluid.ambient;
            out2[i as usize] = 0.0;
        }
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_divergence(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 107)] u: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 108)] v: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 109)] w: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = d.scalar * divergence(&d.fluid, i, Velocity { u, v, w }, flags);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_apply(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = apply_poisson(d.level(), flags, a, i);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_residual(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = a[i as usize] - apply_poisson(d.level(), flags, b, i);
    }
}

/// The multigrid's coarsest level solved in one workgroup (`coarse_solve`'s
/// half-sweeps, each split among the lanes, a barrier after each): one
/// dispatch where the sweeps into a second array take 64. Dispatch exactly
/// `COARSE_LANES` invocations, `out` (the level's `x`) cleared.
#[spirv(compute(threads(64)))]
pub fn fluid_coarse_solve(
    #[spirv(local_invocation_index)] lane: u32,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let n = params[0].level();
    let mut k = 0;
    while k < COARSE_HALF_SWEEPS {
        gauss_seidel_in_place(n, flags, a, out, lane, COARSE_LANES, coarse_colour(k));
        barrier();
        k += 1;
    }
}

/// Every lane's writes to the storage buffers visible to the workgroup
/// before any lane goes on (the CPU runs one lane: nothing to wait for).
/// Workgroup scope for both the execution and the memory (the Vulkan
/// memory model the module uses refuses device scope without a
/// capability), on storage-buffer memory: GLSL's
/// `controlBarrier(gl_ScopeWorkgroup, gl_ScopeWorkgroup,
/// gl_StorageSemanticsBuffer, gl_SemanticsAcquireRelease)`.
#[cfg(target_arch = "spirv")]
fn barrier() {
    use spirv_std::memory::{Scope, Semantics};
    spirv_std::arch::control_barrier::<
        { Scope::Workgroup as u32 },
        { Scope::Workgroup as u32 },
        { Semantics::UNIFORM_MEMORY.bits() | Semantics::ACQUIRE_RELEASE.bits() },
    >();
}
#[cfg(not(target_arch = "spirv"))]
fn barrier() {}

#[spirv(compute(threads(64)))]
pub fn fluid_gauss_seidel(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = gauss_seidel(d.level(), flags, a, b, i, d.colour);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_restrict(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = restrict(d.level(), a, i);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_prolong(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = prolong(d.level(), flags, a, b, i);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_project(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = project_face(&d.fluid, d.kind, i, out[i as usize], a, flags);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_cg_update(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 113)] out2: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        let k = i as usize;
        let (phi, r) = cg_update(out[k], out2[k], a[k], b[k], d.scalar);
        out[k] = phi;
        out2[k] = r;
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_cg_direction(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = cg_direction(a[i as usize], out[i as usize], d.scalar);
    }
}

#[spirv(compute(threads(64)))]
pub fn fluid_less_mean(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 112)] out: &mut [f32],
) {
    let d = &params[0];
    if let Some(i) = element(id, groups, d) {
        out[i as usize] = less_mean(out[i as usize], flags[i as usize], d.scalar);
    }
}

/// One invocation per `PARTIAL_SPAN` elements (`count` is the vector's
/// length, `colour` 1 when `flags` marks the fluid cells), written from
/// element `nx` of `partials` on (several vectors' partials in one buffer).
#[spirv(compute(threads(64)))]
pub fn fluid_partials(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(num_workgroups)] groups: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 100)] params: &[FluidDispatch],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 101)] a: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 102)] b: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 110)] flags: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 115)] partials: &mut [Vec4],
) {
    let d = &params[0];
    let g = crate::flat_index(id, groups);
    if g < partial_groups(d.count) {
        partials[(d.nx + g) as usize] = partial(a, b, flags, d.colour != 0, d.count, g);
    }
}
