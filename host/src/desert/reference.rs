//! The desert family's part of the reference (`crate::reference`): a
//! terrain's ripples at their full resolution on the surface a reference
//! ray meets (the truth the ripples' level of detail is measured against).

use glam::DVec3;
use slicelight_shaders::desert::ripples::{rippled as ripple_normal_at, RippleRecord, LOD_FULL};

use crate::reference::Surface;
use crate::scene::SceneData;

/// `hit` on the ray `o + t d`, its normal tilted by its terrain's ripples
/// at full resolution (turned toward the ray); `hit` itself without them.
pub(crate) fn rippled(data: &SceneData, o: DVec3, d: DVec3, hit: Surface) -> Surface {
    let bump = data.materials[hit.material as usize].ripples;
    if bump == 0 || hit.triangle == usize::MAX {
        return hit;
    }
    let full = [RippleRecord { lod: LOD_FULL, ..data.desert.ripple_records[(bump - 1) as usize] }];
    let toward = if hit.normal.dot(d) > 0.0 { -hit.normal } else { hit.normal };
    let p = o + d * hit.t;
    let n = ripple_normal_at(
        &data.common,
        &full,
        &data.desert.ripple_normals,
        1,
        &data.triangles[hit.triangle],
        o.as_vec3(),
        p.as_vec3(),
        toward.as_vec3(),
    );
    Surface { normal: n.as_dvec3().normalize(), ..hit }
}
