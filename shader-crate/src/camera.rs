//! The pinhole camera: view rays through sub-pixel sample positions.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::glam::{Vec2, Vec3, Vec4Swizzles};
use crate::types::CommonParams;

/// Position of sub-pixel sample `index` of `count` inside the pixel, each
/// coordinate in [0, 1) from the pixel's top-left corner: stratified, so
/// that a box filter over them is a low-variance pixel average.
///
/// `count` = 1 is the pixel centre. A square count `k^2` is the `k x k` grid
/// of cell centres. Any other count puts sample `i` in column stratum
/// `(i + 0.5) / count` and its row by the golden-ratio sequence
/// `frac(0.5 + i phi)`, which keeps the rows spread for every count.
pub fn sample_offset(index: u32, count: u32) -> Vec2 {
    if count <= 1 {
        return Vec2::splat(0.5);
    }
    let k = (count as f32).sqrt().round() as u32;
    if k * k == count {
        let (i, j) = (index % k, index / k);
        return Vec2::new((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
    }
    let x = (index as f32 + 0.5) / count as f32;
    let y = 0.5 + index as f32 * 0.618_034;
    Vec2::new(x, y - y.floor())
}

/// Normalised device coordinates in [-1, 1] (y up) of the point at `offset`
/// inside pixel `(x, y)` (row 0 at the top).
pub fn pixel_ndc(params: &CommonParams, x: u32, y: u32, offset: Vec2) -> Vec2 {
    Vec2::new(
        2.0 * (x as f32 + offset.x) / params.width as f32 - 1.0,
        1.0 - 2.0 * (y as f32 + offset.y) / params.height as f32,
    )
}

/// Unit view ray through the current sub-pixel sample (`params.sample_index`)
/// of pixel `(x, y)`: origin and direction.
pub fn camera_ray(params: &CommonParams, x: u32, y: u32) -> (Vec3, Vec3) {
    let offset = sample_offset(params.sample_index, params.samples_per_pixel);
    let ndc = pixel_ndc(params, x, y, offset);
    let dir = params.camera_forward.xyz() + params.camera_right.xyz() * ndc.x + params.camera_up.xyz() * ndc.y;
    (params.camera_position.xyz(), dir.normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_sample_is_the_centre_and_squares_are_grids() {
        assert_eq!(sample_offset(0, 1), Vec2::splat(0.5));
        let four: [Vec2; 4] = core::array::from_fn(|i| sample_offset(i as u32, 4));
        assert_eq!(four, [Vec2::new(0.25, 0.25), Vec2::new(0.75, 0.25), Vec2::new(0.25, 0.75), Vec2::new(0.75, 0.75)]);
    }

    #[test]
    fn every_count_is_stratified_in_x_and_inside_the_pixel() {
        for count in 1..=40u32 {
            let mut columns = vec![0u32; count as usize];
            let mut mean = Vec2::ZERO;
            for i in 0..count {
                let o = sample_offset(i, count);
                assert!(o.cmpge(Vec2::ZERO).all() && o.cmplt(Vec2::ONE).all(), "{count}: {o}");
                mean += o / count as f32;
                let k = (count as f32).sqrt().round() as u32;
                if k * k != count {
                    columns[(o.x * count as f32) as usize] += 1;
                }
            }
            assert!(columns.iter().all(|c| *c <= 1), "{count}: {columns:?}");
            // A box filter over the samples centres on the pixel (within the
            // stratification of 1/count in each axis).
            assert!(
                (mean - Vec2::splat(0.5)).abs().max_element() <= 0.5 / count as f32 + 0.2 / (count as f32).sqrt(),
                "{count}: {mean}"
            );
        }
    }
}
