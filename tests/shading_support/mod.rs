//! Test data for the shading tests: a seeded RNG, skewed (gamma, z) samples from a known Psi,
//! and a physically based frame of a camera inside an analytic airway (NOT rendered with Psi).

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]
#![allow(dead_code)]

pub mod physical_frame;

use bronchosim::shading::SampleSet;

#[path = "../common/rng.rs"]
mod rng;
pub use rng::Rng;

/// Psi for parameters (c_0..c_3, d_1..d_3) at (gamma, r).
pub fn psi(p: &[f64; 7], gamma: f64, r: f64) -> f64 {
    let b = |t: f64| {
        let s = 1.0 - t;
        [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t]
    };
    let bg = b(gamma);
    let br = b(r);
    (p[0] * bg[0] + p[1] * bg[1] + p[2] * bg[2] + p[3] * bg[3])
        * (br[0] + p[4] * br[1] + p[5] * br[2] + p[6] * br[3])
}

/// Where a frame's samples lie: like a camera looking down a tube, most pixels see the far
/// wall at grazing angles (gamma ≈ R / z), a few see the near wall head-on; a thin uniform
/// background covers the rest of the domain sparsely. Returns (gamma, r) pairs.
pub fn skewed_domain(rng: &mut Rng, n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|_| {
            if rng.uniform() < 0.04 {
                // Sparse background over the whole domain.
                (0.05 + 0.95 * rng.uniform(), rng.uniform())
            } else {
                // Dense cluster: far and grazing dominates (depth skewed towards r = 1).
                let r = 1.0 - rng.uniform().powi(2);
                let z = 6.0 + 34.0 * r; // mm
                let g = (7.0 / z + 0.07 * rng.normal()).clamp(0.05, 1.0);
                (g, r)
            }
        })
        .collect()
}

/// A SampleSet with z_min = 6, z_max = 40 mm from (gamma, r) pairs and per-channel intensities.
pub fn sample_set(
    domain: &[(f64, f64)],
    mut rgb: impl FnMut(usize, f64, f64) -> [f64; 3],
) -> SampleSet {
    let mut s = SampleSet {
        z_min: 6.0,
        z_max: 40.0,
        ..Default::default()
    };
    for (i, &(g, r)) in domain.iter().enumerate() {
        s.gamma.push(g as f32);
        s.z.push((6.0 + 34.0 * r) as f32);
        let v = rgb(i, g, r);
        for ch in 0..3 {
            s.rgb[ch].push(v[ch] as f32);
        }
    }
    s
}
