//! A physically based endoscope frame, rendered WITHOUT Psi: a camera inside a tapered, gently
//! bent tube with cartilage-ring relief; a co-located spot light with a cone falloff and
//! inverse-square attenuation; Lambert + GGX specular (wet mucosa); an albedo with colour
//! variation and darker vessel lines; auto-gain, sensor noise, clipping at 1 and 8-bit sRGB
//! quantisation. Geometry (gamma, z per pixel) is exact up to the root finder (1e-6 mm).

#[path = "../common/physics.rs"]
mod physics;
use super::Rng;
use physics::{brdf_cos, srgb_decode, srgb_encode};
use std::f64::consts::PI;

/// One rendered frame, per-pixel slices in the layout `extract_samples` takes.
pub struct Frame {
    pub width: usize,
    pub height: usize,
    /// cos(view ray, inward normal); 0 where no hit.
    pub gamma: Vec<f32>,
    /// Distance camera → surface (mm); 0 where no hit.
    pub z: Vec<f32>,
    /// Linear RGB 0..1, interleaved.
    pub rgb: Vec<f32>,
    /// The frame's shading with the mean albedo (gain × light × BRDF), before noise and
    /// clipping: what a perfect shading model could explain.
    pub true_shading: Vec<[f32; 3]>,
}

/// The airway: axis bent in x as z grows, radius tapering with rings; `s` is the axial position (mm).
struct Tube;

impl Tube {
    const R0: f64 = 8.0;
    const LENGTH: f64 = 70.0;
    fn axis_x(s: f64) -> f64 {
        0.004 * s * s / 2.0
    }
    fn radius(s: f64) -> f64 {
        Self::R0 * (1.0 - 0.006 * s) + 0.18 * (2.0 * PI * s / 4.0).sin()
    }
    /// Negative inside the lumen.
    fn f(p: [f64; 3]) -> f64 {
        (p[0] - Self::axis_x(p[2])).hypot(p[1]) - Self::radius(p[2])
    }
    /// Unit normal facing into the lumen (-grad f).
    fn inward_normal(p: [f64; 3]) -> [f64; 3] {
        let h = 1e-4;
        let mut g = [0.0; 3];
        for k in 0..3 {
            let mut a = p;
            let mut b = p;
            a[k] += h;
            b[k] -= h;
            g[k] = (Self::f(a) - Self::f(b)) / (2.0 * h);
        }
        let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        [-g[0] / n, -g[1] / n, -g[2] / n]
    }
}

/// Mucosa albedo at surface point p: base colour, slow variation, vessel lines.
fn albedo(p: [f64; 3]) -> [f64; 3] {
    let s = p[2];
    let phi = p[1].atan2(p[0] - Tube::axis_x(s));
    let arc = phi * Tube::R0; // mm around the wall
    let base = [0.78, 0.40, 0.34];
    let slow = 1.0 + 0.07 * (0.21 * s + 0.9 * phi.sin()).sin();
    // Vessels: thin meandering lines (two families), darker and redder.
    let v1 = ((0.9 * s + 1.5 * (0.3 * arc).sin()) * 1.3).sin().abs();
    let v2 = ((0.55 * arc + 1.2 * (0.25 * s).sin()) * 1.1).sin().abs();
    let vessel = v1 < 0.07 || v2 < 0.05;
    let tint = if vessel { [0.55, 0.30, 0.38] } else { [1.0; 3] };
    std::array::from_fn(|c| base[c] * slow * tint[c])
}

/// Mean albedo, for the true-shading reference.
const MEAN_ALBEDO: [f64; 3] = [0.78, 0.40, 0.34];

/// Render a `size` x `size` frame from a camera at `eye` (world mm), looking along `forward`
/// (tilted off the tube axis), 100-degree field of view; `seed` drives the noise.
/// `cone_exponent`: the light's angular profile is cos^k of the angle off the optical axis.
pub fn render(
    size: usize,
    eye: [f64; 3],
    tilt_deg: [f64; 2],
    cone_exponent: i32,
    seed: u64,
) -> Frame {
    let n = size * size;
    let f_px = (size as f64 / 2.0) / (50f64.to_radians()).tan();
    let c = (size as f64 - 1.0) / 2.0;
    // Camera axes: OpenCV (+x right, +y down, +z forward), rotated by the tilt about x then y.
    let (ax, ay) = (tilt_deg[0].to_radians(), tilt_deg[1].to_radians());
    let rot = |v: [f64; 3]| -> [f64; 3] {
        let v1 = [
            v[0],
            v[1] * ax.cos() - v[2] * ax.sin(),
            v[1] * ax.sin() + v[2] * ax.cos(),
        ];
        [
            v1[0] * ay.cos() + v1[2] * ay.sin(),
            v1[1],
            -v1[0] * ay.sin() + v1[2] * ay.cos(),
        ]
    };
    let optical_axis = rot([0.0, 0.0, 1.0]);
    let mut gamma = vec![0f32; n];
    let mut z = vec![0f32; n];
    let mut radiance = vec![[0f64; 3]; n];
    let mut shading = vec![[0f64; 3]; n];
    for py in 0..size {
        for px in 0..size {
            let d = rot([(px as f64 - c) / f_px, (py as f64 - c) / f_px, 1.0]);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let d = [d[0] / len, d[1] / len, d[2] / len];
            let at = |t: f64| [eye[0] + t * d[0], eye[1] + t * d[1], eye[2] + t * d[2]];
            // March to the first sign change, then bisect.
            let (mut t0, mut t1) = (0.0, f64::NAN);
            let step = 0.2;
            let mut t = step;
            while t < 120.0 {
                let p = at(t);
                if p[2] > Tube::LENGTH {
                    break; // the lumen continues beyond: no surface hit
                }
                if Tube::f(p) >= 0.0 {
                    t1 = t;
                    break;
                }
                t0 = t;
                t += step;
            }
            if t1.is_nan() {
                continue;
            }
            for _ in 0..40 {
                let m = 0.5 * (t0 + t1);
                if Tube::f(at(m)) >= 0.0 {
                    t1 = m;
                } else {
                    t0 = m;
                }
            }
            let th = 0.5 * (t0 + t1);
            let p = at(th);
            let nrm = Tube::inward_normal(p);
            let g = -(d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2]);
            let i = py * size + px;
            gamma[i] = g as f32;
            z[i] = th as f32;
            if g <= 0.0 {
                continue;
            }
            // Spot light: cone falloff in the angle off the optical axis, inverse square.
            let cos_axis = d[0] * optical_axis[0] + d[1] * optical_axis[1] + d[2] * optical_axis[2];
            let cone = cos_axis.max(0.0).powi(cone_exponent);
            let light = 400.0 * cone / (th * th);
            let (diff, spec) = brdf_cos(g);
            let a = albedo(p);
            for ch in 0..3 {
                radiance[i][ch] = light * (a[ch] * diff + spec);
                shading[i][ch] = light * (MEAN_ALBEDO[ch] * diff + spec);
            }
        }
    }
    // Auto-gain: the 90th percentile of hit luminance goes to 0.6.
    let mut lum: Vec<f64> = radiance
        .iter()
        .zip(&z)
        .filter(|(_, zz)| **zz > 0.0)
        .map(|(v, _)| 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2])
        .collect();
    let k = ((lum.len() as f64 * 0.9) as usize).min(lum.len() - 1);
    let (_, p90, _) = lum.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    let gain = 0.6 / *p90;
    let mut rng = Rng::new(seed);
    let mut rgb = vec![0f32; 3 * n];
    let mut true_shading = vec![[0f32; 3]; n];
    for i in 0..n {
        for ch in 0..3 {
            let v = gain * radiance[i][ch];
            // Poisson–Gaussian sensor noise, clipping, 8-bit sRGB quantisation.
            let sigma = (0.0004 * v + 0.002f64.powi(2)).sqrt();
            let noisy = (v + sigma * rng.normal()).clamp(0.0, 1.0);
            let code = (srgb_encode(noisy) * 255.0).round() / 255.0;
            rgb[3 * i + ch] = srgb_decode(code) as f32;
            true_shading[i][ch] = (gain * shading[i][ch]) as f32;
        }
    }
    Frame {
        width: size,
        height: size,
        gamma,
        z,
        rgb,
        true_shading,
    }
}
