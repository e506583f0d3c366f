//! The phantom's frame renderer: a physically motivated bronchoscope image, deliberately NOT
//! the paper's Psi, so fitting Psi to these frames is a real approximation.
//!
//! Per pixel (from the ray-cast G-buffer): a point light at the camera centre with a spot
//! cone `s(θ) = cos^k θ` (θ off the optical axis, k chosen so s = 1/2 at the half angle, faded
//! to 0 at the cut-off), inverse-square falloff `1/z²`, and a wet-mucosa BRDF: Lambert
//! `(1 - F0) albedo / π` plus an isotropic GGX specular lobe (Smith masking, Schlick Fresnel
//! at normal incidence since light and viewer coincide). A small inter-reflection term
//! proportional to the frame's mean direct radiance and the local albedo is added. Then the
//! sensor: a per-frame auto-gain (mean linear luminance to a target, capped so only a small
//! percentile of pixels clips), Poisson–Gaussian noise and clipping at 1.0 (saturation).

use super::baked_albedo::PhantomAlbedo;
use crate::camera::Camera;
use crate::image::Frame;
use crate::math::Affine;
use crate::raycast::{cast_frame_with, RayTable, Scene};
use crate::rng::Pcg32;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The light and reflectance model (unit-gain radiance). Angles in degrees.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LightModel {
    /// Angle off the optical axis where the spot cone falls to half power (degrees).
    pub cone_half_angle_deg: f64,
    /// Angle where the cone has faded to zero (degrees); the fade starts 15° earlier.
    pub cone_cutoff_deg: f64,
    /// Light intensity (radiance scale at 1 mm, before the gain).
    pub intensity: f64,
    /// GGX roughness (perceptual; alpha = roughness²).
    pub roughness: f64,
    /// Fresnel reflectance at normal incidence of the wet mucosa.
    pub f0: f64,
    /// Inter-reflection: this fraction of the frame's mean direct luminance, times
    /// albedo / 0.3, is added to every surface pixel.
    pub ambient_fraction: f64,
}

impl Default for LightModel {
    fn default() -> Self {
        LightModel {
            cone_half_angle_deg: 60.0,
            cone_cutoff_deg: 88.0,
            intensity: 100.0,
            roughness: 0.3,
            f0: 0.03,
            ambient_fraction: 0.04,
        }
    }
}

impl LightModel {
    /// Cone exponent k with cos^k(half angle) = 1/2.
    pub fn cone_exponent(&self) -> f64 {
        0.5f64.ln() / self.cone_half_angle_deg.to_radians().cos().ln()
    }

    /// Spot-cone profile at `cos_theta` (cosine of the angle off the optical axis).
    #[inline]
    pub fn cone(&self, cos_theta: f64, k: f64) -> f64 {
        if cos_theta <= 0.0 {
            return 0.0;
        }
        let th = cos_theta.min(1.0).acos().to_degrees();
        let fade = 1.0 - smoothstep(self.cone_cutoff_deg - 15.0, self.cone_cutoff_deg, th);
        cos_theta.powf(k) * fade
    }

    /// Diffuse and specular factors at `gamma` (cosine between the normal and the direction
    /// to the light = viewer): radiance = E (albedo · diffuse + specular), E the irradiance
    /// scale `intensity · cone / z²`.
    #[inline]
    pub fn brdf_cos(&self, gamma: f64) -> (f64, f64) {
        let g = gamma.clamp(1e-4, 1.0);
        let a = self.roughness * self.roughness;
        let a2 = a * a;
        let den = g * g * (a2 - 1.0) + 1.0;
        let d = a2 / (std::f64::consts::PI * den * den);
        let g1 = 2.0 * g / (g + (a2 + (1.0 - a2) * g * g).sqrt());
        // BRDF D G F / (4 cos_l cos_v) times cos_l, with cos_l = cos_v = g.
        let spec = d * g1 * g1 * self.f0 / (4.0 * g);
        let diffuse = (1.0 - self.f0) * g / std::f64::consts::PI;
        (diffuse, spec)
    }

    /// Direct radiance (unit gain, linear RGB) of a surface of linear `albedo` at distance `z`
    /// (mm), `cos_gamma` between its normal and the ray, seen along a ray `cos_theta` off the
    /// optical axis; `k` is [`cone_exponent`](Self::cone_exponent).
    #[inline]
    pub fn direct_radiance(
        &self,
        albedo: [f32; 3],
        cos_theta: f64,
        cos_gamma: f64,
        z: f64,
        k: f64,
    ) -> [f64; 3] {
        let e = self.intensity * self.cone(cos_theta, k) / (z * z).max(1e-6);
        let (dif, spec) = self.brdf_cos(cos_gamma);
        albedo.map(|c| e * (c as f64 * dif + spec))
    }

    /// The inter-reflected irradiance of a frame whose mean direct luminance is
    /// `mean_direct_luminance`: every surface pixel adds this times its albedo.
    #[inline]
    pub fn interreflection(&self, mean_direct_luminance: f64) -> f64 {
        self.ambient_fraction * mean_direct_luminance / 0.3
    }
}

/// The sensor: auto-gain, noise, saturation.
#[derive(Clone, Debug, Serialize)]
pub struct SensorModel {
    /// Auto-gain target for the frame's mean linear luminance.
    pub target_mean: f64,
    /// The gain is capped so that at most this fraction of pixels has a channel above 1.
    pub max_clipped_fraction: f64,
    /// Full-well capacity in electrons at signal 1.0 (shot noise variance = signal / this).
    pub full_well_electrons: f64,
    /// Read-noise standard deviation (linear units of full scale).
    pub read_noise: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel {
            target_mean: 0.18,
            max_clipped_fraction: 0.02,
            full_well_electrons: 4000.0,
            read_noise: 0.002,
        }
    }
}

/// Pixel rays with `ss × ss` sub-samples per pixel (a stratified grid), for antialiasing.
#[derive(Clone, Debug)]
pub struct SubpixelRays {
    /// Fine ray table: `width·ss × height·ss` rays, row-major.
    pub table: RayTable,
    /// Sub-samples per pixel along each axis.
    pub ss: u32,
    /// Output image width (pixels).
    pub width: u32,
    /// Output image height (pixels).
    pub height: u32,
}

impl SubpixelRays {
    /// Tabulate the rays of `camera` (through its distortion) with `ss²` samples per pixel.
    pub fn new(camera: &Camera, ss: u32) -> Self {
        let ss = ss.max(1);
        let (fw, fh) = (camera.width * ss, camera.height * ss);
        let dirs = (0..(fw * fh) as usize)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                let (x, y) = ((i % fw as usize) as f64, (i / fw as usize) as f64);
                let o = |q: f64| (q + 0.5) / ss as f64 - 0.5;
                let d = camera.pixel_ray(o(x), o(y));
                [d.x as f32, d.y as f32, d.z as f32]
            })
            .collect();
        SubpixelRays {
            table: RayTable {
                width: fw,
                height: fh,
                dirs,
            },
            ss,
            width: camera.width,
            height: camera.height,
        }
    }
}

/// Unit-gain radiance of one view (before the sensor).
#[derive(Clone, Debug)]
pub struct Radiance {
    /// Linear RGB radiance per pixel (unit gain), row-major, 3 values per pixel.
    pub frame: Frame,
    /// Fraction of each pixel's sub-samples that hit the surface.
    pub coverage: Vec<f32>,
}

/// Render the unit-gain radiance seen from `camera_to_world` (world mm).
pub fn render_radiance(
    scene: &Scene,
    rays: &SubpixelRays,
    camera_to_world: &Affine,
    albedo: &PhantomAlbedo,
    light: &LightModel,
) -> Radiance {
    let gb = cast_frame_with(scene, &rays.table, camera_to_world);
    let k = light.cone_exponent();
    // Direct radiance and albedo per sub-sample.
    let samples: Vec<([f32; 3], [f32; 3], bool)> = (0..gb.tri.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            if !gb.hit(i) {
                return ([0.0; 3], [0.0; 3], false);
            }
            let a = albedo.at(gb.tri[i], gb.bary[i], gb.point[i]);
            let cos_t = rays.table.dirs[i][2] as f64;
            let l = light
                .direct_radiance(a, cos_t, gb.gamma[i] as f64, gb.z[i] as f64, k)
                .map(|v| v as f32);
            (l, a, true)
        })
        .collect();
    let lum = |c: &[f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let hits = samples.iter().filter(|s| s.2).count().max(1);
    let mean_direct: f64 = samples
        .iter()
        .filter(|s| s.2)
        .map(|s| lum(&s.0) as f64)
        .sum::<f64>()
        / hits as f64;
    let amb = light.interreflection(mean_direct) as f32;
    let (w, h, ss) = (rays.width as usize, rays.height as usize, rays.ss as usize);
    let fw = w * ss;
    let norm = 1.0 / (ss * ss) as f32;
    let mut frame = Frame::new(rays.width, rays.height);
    let mut coverage = vec![0f32; w * h];
    frame
        .rgb
        .par_chunks_mut(3 * w)
        .zip(coverage.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, cov))| {
            for x in 0..w {
                let mut acc = [0f32; 3];
                let mut n = 0;
                for sy in 0..ss {
                    for sx in 0..ss {
                        let s = &samples[(y * ss + sy) * fw + x * ss + sx];
                        if s.2 {
                            n += 1;
                            for ((a, l), al) in acc.iter_mut().zip(s.0).zip(s.1) {
                                *a += l + amb * al;
                            }
                        }
                    }
                }
                for c in 0..3 {
                    row[3 * x + c] = acc[c] * norm;
                }
                cov[x] = n as f32 * norm;
            }
        });
    Radiance { frame, coverage }
}

/// The auto-exposure gain of a unit-gain radiance image: mean luminance to the target, capped
/// so at most `max_clipped_fraction` of the pixels have a channel above 1.
pub fn auto_gain(radiance: &Frame, sensor: &SensorModel) -> f64 {
    let n = (radiance.width * radiance.height) as usize;
    let mut peak: Vec<f32> = radiance
        .rgb
        .chunks_exact(3)
        .map(|c| c[0].max(c[1]).max(c[2]))
        .collect();
    let mean: f64 = radiance
        .rgb
        .chunks_exact(3)
        .map(|c| (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) as f64)
        .sum::<f64>()
        / n.max(1) as f64;
    if mean <= 0.0 {
        return 1.0;
    }
    let g = sensor.target_mean / mean;
    let q = ((1.0 - sensor.max_clipped_fraction) * (n.saturating_sub(1)) as f64).round() as usize;
    peak.select_nth_unstable_by(q.min(n - 1), f32::total_cmp);
    let p = peak[q.min(n - 1)] as f64;
    if p > 0.0 {
        g.min(1.0 / p)
    } else {
        g
    }
}

/// Apply `gain`, Poisson–Gaussian noise (seeded per row, so the result does not depend on
/// the thread schedule) and saturation at 1.0. `noise = false` gives the clean image.
pub fn expose(
    radiance: &Frame,
    gain: f64,
    sensor: &SensorModel,
    noise: bool,
    seed: u64,
    stream: u64,
) -> Frame {
    let mut out = radiance.clone();
    let w = radiance.width as usize;
    out.rgb
        .par_chunks_mut(3 * w)
        .enumerate()
        .for_each(|(y, row)| {
            let mut rng = Pcg32::new(seed, (stream << 20) | y as u64);
            // Shot and read noise are independent Gaussians: one deviate with their summed
            // variance, two deviates per Box-Muller pair.
            let mut spare = None;
            let read_var = sensor.read_noise * sensor.read_noise;
            for v in row.iter_mut() {
                let s = *v as f64 * gain;
                let x = if noise {
                    let n = spare.take().unwrap_or_else(|| {
                        let (a, b) = rng.normal_pair();
                        spare = Some(b);
                        a
                    });
                    s + (s.max(0.0) / sensor.full_well_electrons + read_var).sqrt() * n
                } else {
                    s
                };
                *v = x.clamp(0.0, 1.0) as f32;
            }
        });
    out
}

#[inline]
fn smoothstep(a: f64, b: f64, x: f64) -> f64 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_model_known_values() {
        let l = LightModel::default();
        let k = l.cone_exponent();
        assert!((l.cone(1.0, k) - 1.0).abs() < 1e-12);
        assert!((l.cone(60f64.to_radians().cos(), k) - 0.5).abs() < 1e-9);
        assert_eq!(l.cone(89f64.to_radians().cos(), k), 0.0);
        // Lambert part at normal incidence is (1 - F0)/π; GGX peaks at normal incidence with
        // D = 1/(π α²), G = 1: spec = F0 / (4 π α²).
        let (d, s) = l.brdf_cos(1.0);
        assert!((d - 0.97 / std::f64::consts::PI).abs() < 1e-12);
        let a = 0.09f64;
        assert!(
            (s - 0.03 / (4.0 * std::f64::consts::PI * a * a)).abs() < 1e-9,
            "{s}"
        );
        // The lobe is narrow: at 30° off the normal the specular is below 2 % of its peak.
        let (_, s30) = l.brdf_cos(30f64.to_radians().cos());
        assert!(s30 < 0.02 * s, "{s30} vs {s}");
    }

    #[test]
    fn auto_gain_hits_the_target_and_expose_clips() {
        let mut f = Frame::new(10, 10);
        for (i, v) in f.rgb.iter_mut().enumerate() {
            *v = 0.01 * (i / 3) as f32 / 99.0;
        }
        let sensor = SensorModel {
            max_clipped_fraction: 0.5,
            ..Default::default()
        };
        let g = auto_gain(&f, &sensor);
        // Mean of a ramp 0..0.01 is 0.005 (luminance weights sum to 1).
        assert!((g * 0.005 - 0.18).abs() < 1e-4, "gain {g}");
        let e = expose(&f, 301.0, &sensor, false, 1, 0);
        let clipped = e.rgb.iter().filter(|&&v| v >= 1.0).count();
        // 301 · 0.01 · i/99 >= 1 for i >= 33: 67 pixels × 3 channels.
        assert_eq!(clipped, 67 * 3);
        let n1 = expose(&f, 20.0, &sensor, true, 1, 0);
        let n2 = expose(&f, 20.0, &sensor, true, 1, 0);
        assert_eq!(n1.rgb, n2.rgb);
        assert_ne!(n1.rgb, expose(&f, 20.0, &sensor, true, 2, 0).rgb);
    }
}
