//! The reflectance and sensor coding of the synthetic test frames, shared by the shading,
//! calibrated-light and texture test supports (included with `#[path]`; not every includer
//! uses every item).
#![allow(dead_code)]

use std::f64::consts::PI;

/// Lambert (per unit albedo) and GGX specular (roughness 0.3, F0 0.025) for a light at the
/// eye, where N·L = N·V = N·H = gamma and V·H = 1; both times the cosine.
pub fn brdf_cos(gamma: f64) -> (f64, f64) {
    let a2: f64 = 0.3 * 0.3;
    let d = a2 / (PI * (gamma * gamma * (a2 - 1.0) + 1.0).powi(2));
    let g1 = 2.0 * gamma / (gamma + (a2 + (1.0 - a2) * gamma * gamma).sqrt());
    let spec = 0.025 * d * g1 * g1 / (4.0 * gamma * gamma);
    (gamma / PI, spec * gamma)
}

/// Linear light to sRGB (no clamping).
pub fn srgb_encode(x: f64) -> f64 {
    if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB to linear light.
pub fn srgb_decode(x: f64) -> f64 {
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}
