//! The cameras (pinhole and equidistant fisheye): view rays through
//! sub-pixel sample positions.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::glam::{Vec2, Vec3, Vec4Swizzles};
use crate::types::{CommonParams, PROJECTION_FISHEYE};
use core::f32::consts::FRAC_PI_2;

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

/// A fisheye's image coordinates of the point at `offset` inside pixel
/// `(x, y)`: the inscribed circle of the image is the unit circle (y up).
pub fn fisheye_coords(params: &CommonParams, x: u32, y: u32, offset: Vec2) -> Vec2 {
    let size = params.width.min(params.height) as f32;
    Vec2::new(
        (2.0 * (x as f32 + offset.x) - params.width as f32) / size,
        (params.height as f32 - 2.0 * (y as f32 + offset.y)) / size,
    )
}

/// Whether the current sub-pixel sample of pixel `(x, y)` sees the scene:
/// always for a pinhole, inside the image circle for a fisheye.
pub fn in_image(params: &CommonParams, x: u32, y: u32) -> bool {
    if params.projection != PROJECTION_FISHEYE {
        return true;
    }
    let offset = sample_offset(params.sample_index, params.samples_per_pixel);
    fisheye_coords(params, x, y, offset).length_squared() <= 1.0
}

/// Unit view ray through the current sub-pixel sample (`params.sample_index`)
/// of pixel `(x, y)`: origin and direction. A fisheye's ray is at the angle
/// `90 deg * |c|` from the view direction, `c` the sample's `fisheye_coords`
/// (clamped to the circle; outside it see `in_image`).
pub fn camera_ray(params: &CommonParams, x: u32, y: u32) -> (Vec3, Vec3) {
    let offset = sample_offset(params.sample_index, params.samples_per_pixel);
    (params.camera_position.xyz(), ray_direction(params, x, y, offset))
}

/// The unit direction of the view ray through the point `offset` of pixel
/// `(x, y)` (`camera_ray`'s, at any offset: ray differentials take it at
/// the sample cell's edges).
pub fn ray_direction(params: &CommonParams, x: u32, y: u32, offset: Vec2) -> Vec3 {
    let forward = params.camera_forward.xyz();
    if params.projection == PROJECTION_FISHEYE {
        let c = fisheye_coords(params, x, y, offset);
        let radius = c.length();
        let theta = radius.min(1.0) * FRAC_PI_2;
        let side = if radius > 0.0 {
            (params.camera_right.xyz() * c.x + params.camera_up.xyz() * c.y) / radius
        } else {
            Vec3::ZERO
        };
        return (forward * theta.cos() + side * theta.sin()).normalize();
    }
    pinhole_direction(params, pixel_ndc(params, x, y, offset))
}

/// The unit direction of a pinhole camera's ray through the point `ndc`
/// (normalised device coordinates, `pixel_ndc`).
pub fn pinhole_direction(params: &CommonParams, ndc: Vec2) -> Vec3 {
    (params.camera_forward.xyz() + params.camera_right.xyz() * ndc.x + params.camera_up.xyz() * ndc.y).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fisheye_is_equidistant_with_the_zenith_at_the_centre() {
        let params = CommonParams {
            camera_forward: crate::glam::Vec4::new(0.0, 1.0, 0.0, 0.0),
            camera_right: crate::glam::Vec4::new(1.0, 0.0, 0.0, 0.0),
            camera_up: crate::glam::Vec4::new(0.0, 0.0, -1.0, 0.0),
            width: 101,
            height: 101,
            samples_per_pixel: 1,
            projection: PROJECTION_FISHEYE,
            ..Default::default()
        };
        // The centre pixel looks along the view direction (the zenith).
        let (_, d) = camera_ray(&params, 50, 50);
        assert!((d - Vec3::Y).length() < 1e-6, "{d}");
        // Angle from the view direction grows linearly with the radius:
        // pixel column 50 + k is at radius (2k)/101 of the circle.
        for k in [5u32, 20, 40, 50] {
            let (_, d) = camera_ray(&params, 50 + k, 50);
            let expected = 2.0 * k as f32 / 101.0 * FRAC_PI_2;
            assert!((d.y.clamp(-1.0, 1.0).acos() - expected).abs() < 1e-5, "{k}: {d}");
            assert!(d.x > 0.0 && d.z.abs() < 1e-6);
            assert!(in_image(&params, 50 + k, 50));
        }
        // The corners are outside the image circle.
        assert!(!in_image(&params, 0, 0) && !in_image(&params, 100, 100));
    }

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
