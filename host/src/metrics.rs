//! Image differences, as the papers report them.

use glam::{DVec3, Vec4};

/// Differences between an image and its reference, over all pixels and channels.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Difference {
    /// RMS of the radiance difference divided by the reference's largest value.
    pub rms_relative: f64,
    /// Largest radiance difference divided by the reference's largest value.
    pub max_relative: f64,
    /// RMS difference of the tone-mapped 8-bit images, % of 255 (the 2002 paper's measure).
    pub rms_8bit_percent: f64,
    /// Largest difference of the tone-mapped 8-bit images, % of 255.
    pub max_8bit_percent: f64,
    /// The image's energy over the reference's: the sums of all pixels'
    /// channels, linear radiance (1 for an empty reference and image).
    pub energy_ratio: f64,
}

/// The RMS and the largest difference over all pixels and channels, each
/// divided by the reference's largest channel value: the one relative
/// measure of the project (whole images, the sky bench's pixels, the
/// references' convergence between rounds).
pub fn relative_error(image: &[DVec3], reference: &[DVec3]) -> (f64, f64) {
    assert_eq!(image.len(), reference.len(), "images of different sizes");
    let peak = reference.iter().map(|p| p.max_element()).fold(0.0f64, f64::max).max(1e-300);
    let (mut sum2, mut max) = (0.0, 0.0f64);
    for (a, b) in image.iter().zip(reference) {
        let d = (*a - *b).abs();
        sum2 += d.length_squared();
        max = max.max(d.max_element());
    }
    ((sum2 / (3 * image.len().max(1)) as f64).sqrt() / peak, max / peak)
}

/// Compares `image` against `reference` (both linear rgb radiance), with the
/// 8-bit measures taken after the PNG tone mapping at `exposure`.
pub fn difference(image: &[DVec3], reference: &[DVec3], exposure: f32) -> Difference {
    let (rms_relative, max_relative) = relative_error(image, reference);
    let (mut sum2_8, mut max_8) = (0.0, 0.0f64);
    for (a, b) in image.iter().zip(reference) {
        for c in 0..3 {
            let a8 = crate::output::to_8bit(a[c] as f32, exposure) as f64;
            let b8 = crate::output::to_8bit(b[c] as f32, exposure) as f64;
            let d8 = (a8 - b8).abs() / 255.0 * 100.0;
            sum2_8 += d8 * d8;
            max_8 = max_8.max(d8);
        }
    }
    let n = (image.len() * 3).max(1) as f64;
    Difference {
        rms_relative,
        max_relative,
        rms_8bit_percent: (sum2_8 / n).sqrt(),
        max_8bit_percent: max_8,
        energy_ratio: energy_ratio(image, reference),
    }
}

/// Sum of the image's channels over the reference's (1 where both are 0).
pub fn energy_ratio(image: &[DVec3], reference: &[DVec3]) -> f64 {
    let a: f64 = image.iter().map(|p| p.element_sum()).sum();
    let b: f64 = reference.iter().map(|p| p.element_sum()).sum();
    if b == 0.0 {
        if a == 0.0 {
            1.0
        } else {
            f64::INFINITY
        }
    } else {
        a / b
    }
}

pub fn to_f64(pixels: &[Vec4]) -> Vec<DVec3> {
    pixels.iter().map(|p| p.truncate().as_dvec3()).collect()
}
