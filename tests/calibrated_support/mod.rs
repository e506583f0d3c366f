//! A physically based multi-frame endoscope video with known light, gains and albedo, rendered
//! WITHOUT the calibrated model: a camera moving through a tapered elliptic tube (ray–surface
//! intersection in closed form, so gamma, z and theta are exact); a spot light at the lens with
//! a Gaussian cone profile (not a polynomial in cos theta); Lambert + GGX specular (wet mucosa;
//! the specular part is not scaled by the albedo); inverse-square falloff; an albedo with slow
//! colour variation and darker vessels; per-frame gains drawn in [0.5, 2]; optional uniform
//! inter-reflected light; sensor noise, clipping at 1 and 8-bit sRGB quantisation.

#![allow(dead_code)]
#![allow(clippy::needless_range_loop)]

#[path = "../common/physics.rs"]
mod physics;
use physics::{brdf_cos, srgb_decode, srgb_encode};
use std::f64::consts::PI;

#[path = "../common/rng.rs"]
mod rng;
pub use rng::Rng;

/// The tube: `x²/a0² + y²/b0² = (1 - k z)²` for 0 <= z <= LENGTH (mm); open beyond.
const A0: f64 = 8.5;
const B0: f64 = 7.0;
const TAPER: f64 = 0.005;
const LENGTH: f64 = 90.0;
/// Texel size (mm) of the (axial, around) surface grid used for the albedo refinement.
const TEXEL_MM: f64 = 0.5;

/// Half-intensity angle of the light's cone (degrees).
pub const CONE_HALF_DEG: f64 = 40.0;

/// The light's true angular profile: Gaussian in theta, 1 on the axis, 1/2 at CONE_HALF_DEG.
pub fn cone_profile(theta_deg: f64) -> f64 {
    (-(2f64.ln()) * (theta_deg / CONE_HALF_DEG).powi(2)).exp()
}

/// Base mucosa colour (the albedo's typical value).
pub const BASE_ALBEDO: [f64; 3] = [0.78, 0.40, 0.34];

/// Albedo at axial position z and angle phi around the tube; `slow_amplitude` is the relative
/// amplitude of its slow variation (period about 30 mm along the airway).
pub fn albedo(z: f64, phi: f64, slow_amplitude: f64) -> [f64; 3] {
    let arc = phi * A0;
    let slow = 1.0 + slow_amplitude * (0.21 * z + 0.9 * phi.sin()).sin();
    let v1 = ((0.9 * z + 1.5 * (0.3 * arc).sin()) * 1.3).sin().abs();
    let v2 = ((0.55 * arc + 1.2 * (0.25 * z).sin()) * 1.1).sin().abs();
    let vessel = v1 < 0.07 || v2 < 0.05;
    let tint = if vessel { [0.55, 0.30, 0.38] } else { [1.0; 3] };
    std::array::from_fn(|c| BASE_ALBEDO[c] * slow * tint[c])
}

/// The albedo's slow change of blood content (hyperaemia) at (z, phi): a factor per channel
/// that darkens green and blue about three times as much as red, as haemoglobin does;
/// `amplitude` is its largest log change in red.
pub fn blood_tint(z: f64, phi: f64, amplitude: f64) -> [f64; 3] {
    let m = amplitude * (0.17 * z + 0.8 * phi.cos() + 1.0).sin();
    [(-m).exp(), (-3.2 * m).exp(), (-2.6 * m).exp()]
}

/// A camera pose: eye (mm) and camera → world rotation (columns = camera x, y, z axes).
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub eye: [f64; 3],
    pub rot: [[f64; 3]; 3],
    /// The frame's auto-exposure gain (truth).
    pub gain: f64,
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / l, v[1] / l, v[2] / l]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

impl View {
    /// Looking along (tan yaw, tan pitch, 1), rolled about the optical axis.
    pub fn new(eye: [f64; 3], yaw_deg: f64, pitch_deg: f64, roll_deg: f64, gain: f64) -> View {
        let zc = normalize([
            yaw_deg.to_radians().tan(),
            pitch_deg.to_radians().tan(),
            1.0,
        ]);
        let x0 = normalize(cross([0.0, 1.0, 0.0], zc));
        let y0 = cross(zc, x0);
        let (s, c) = roll_deg.to_radians().sin_cos();
        let xc = std::array::from_fn(|k| c * x0[k] + s * y0[k]);
        let yc = std::array::from_fn(|k| -s * x0[k] + c * y0[k]);
        let rot =
            std::array::from_fn(|r| [[xc, yc, zc][0][r], [xc, yc, zc][1][r], [xc, yc, zc][2][r]]);
        View { eye, rot, gain }
    }
}

/// A pull-through sequence of `n` views with gains drawn log-uniformly in [0.5, 2].
pub fn sequence(n: usize, seed: u64) -> Vec<View> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|f| {
            let u = f as f64 / (n.max(2) - 1) as f64;
            let z = 5.0 + 45.0 * u;
            let eye = [
                2.2 * (7.0 * u).sin() + 0.3 * rng.normal(),
                1.8 * (5.0 * u + 1.0).cos() + 0.3 * rng.normal(),
                z,
            ];
            let yaw = 22.0 * (9.0 * u + 0.5).sin() + 4.0 * rng.normal();
            let pitch = 18.0 * (6.0 * u + 2.0).cos() + 4.0 * rng.normal();
            let roll = 360.0 * rng.uniform();
            let gain = (0.5f64.ln() + rng.uniform() * 4f64.ln()).exp();
            View::new(eye, yaw, pitch, roll, gain)
        })
        .collect()
}

/// One rendered frame (row-major per-pixel slices).
pub struct Frame {
    pub size: usize,
    /// cos(view ray, inward normal); 0 where no hit.
    pub gamma: Vec<f32>,
    /// Distance camera → surface (mm); 0 where no hit.
    pub z: Vec<f32>,
    /// cos of the ray's angle off the optical axis.
    pub cos_theta: Vec<f32>,
    /// Linear RGB 0..1, interleaved.
    pub rgb: Vec<f32>,
    /// Surface texel id; u32::MAX where no hit.
    pub texel: Vec<u32>,
    /// True albedo / BASE_ALBEDO, interleaved; 0 where no hit.
    pub albedo_rel: Vec<f32>,
}

impl Frame {
    /// The frame as the calibrated fit's pooling reads it (texel ids included).
    pub fn data(&self) -> bronchosim::shading::calibrated::FrameData<'_> {
        bronchosim::shading::calibrated::FrameData {
            gamma: &self.gamma,
            z: &self.z,
            cos_theta: &self.cos_theta,
            rgb: &self.rgb,
            texel: Some(&self.texel),
            width: self.size,
        }
    }
}

/// Render options.
#[derive(Clone, Copy, Debug)]
pub struct RenderOptions {
    /// Image side (pixels).
    pub size: usize,
    /// Horizontal field of view (degrees).
    pub fov_deg: f64,
    /// Light power (sets the exposure at gain 1).
    pub power: f64,
    /// Uniform inter-reflected irradiance, as a fraction of the direct irradiance at 10 mm on axis.
    pub ambient: f64,
    /// Relative amplitude of the albedo's slow variation along and around the airway.
    pub slow_albedo: f64,
    /// Largest log change of red in the albedo's slow change of blood content ([`blood_tint`];
    /// 0: none).
    pub slow_blood: f64,
    /// Inter-reflection in proportion to the frame's light: this fraction of the frame's mean
    /// direct luminance, times albedo / 0.3, added to every surface pixel (the phantom's form).
    pub interreflection: f64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            size: 160,
            fov_deg: 100.0,
            power: 90.0,
            ambient: 0.0,
            slow_albedo: 0.08,
            slow_blood: 0.0,
            interreflection: 0.0,
        }
    }
}

/// Closest hit of the ray `o + t d` with the tube wall (t > 0, 0 <= z <= LENGTH).
fn intersect(o: [f64; 3], d: [f64; 3]) -> Option<f64> {
    let (ia, ib) = (1.0 / (A0 * A0), 1.0 / (B0 * B0));
    let l = 1.0 - TAPER * o[2];
    let qa = d[0] * d[0] * ia + d[1] * d[1] * ib - TAPER * TAPER * d[2] * d[2];
    let qb = o[0] * d[0] * ia + o[1] * d[1] * ib + TAPER * d[2] * l;
    let qc = o[0] * o[0] * ia + o[1] * o[1] * ib - l * l;
    let mut roots = Vec::with_capacity(2);
    if qa.abs() < 1e-14 {
        roots.push(-qc / (2.0 * qb));
    } else {
        let disc = qb * qb - qa * qc;
        if disc < 0.0 {
            return None;
        }
        let sq = disc.sqrt();
        roots.push((-qb - sq) / qa);
        roots.push((-qb + sq) / qa);
    }
    roots.sort_by(|a, b| a.total_cmp(b));
    let t = roots.into_iter().find(|&t| t > 1e-9)?;
    let z = o[2] + t * d[2];
    (0.0..=LENGTH).contains(&z).then_some(t)
}

/// Render one frame of `view`; `seed` drives the noise.
pub fn render(view: &View, opts: &RenderOptions, seed: u64) -> Frame {
    let size = opts.size;
    let n = size * size;
    let f_px = (size as f64 / 2.0) / (opts.fov_deg / 2.0).to_radians().tan();
    let c = (size as f64 - 1.0) / 2.0;
    let mut fr = Frame {
        size,
        gamma: vec![0.0; n],
        z: vec![0.0; n],
        cos_theta: vec![0.0; n],
        rgb: vec![0.0; 3 * n],
        texel: vec![u32::MAX; n],
        albedo_rel: vec![0.0; 3 * n],
    };
    let n_around = (2.0 * PI * A0 / TEXEL_MM).round();
    let mut rng = Rng::new(seed);
    let amb_irr = opts.ambient * opts.power / 100.0;
    let mut radiance = vec![[0.0f64; 3]; n];
    let mut albedo_at = vec![[0.0f64; 3]; n];
    for py in 0..size {
        for px in 0..size {
            let i = py * size + px;
            let dc = normalize([(px as f64 - c) / f_px, (py as f64 - c) / f_px, 1.0]);
            fr.cos_theta[i] = dc[2] as f32;
            let r = &view.rot;
            let d = std::array::from_fn(|k| r[k][0] * dc[0] + r[k][1] * dc[1] + r[k][2] * dc[2]);
            let mut rad = [0.0f64; 3];
            if let Some(t) = intersect(view.eye, d) {
                let p: [f64; 3] = std::array::from_fn(|k| view.eye[k] + t * d[k]);
                let grad = normalize([
                    p[0] / (A0 * A0),
                    p[1] / (B0 * B0),
                    TAPER * (1.0 - TAPER * p[2]),
                ]);
                let g = d[0] * grad[0] + d[1] * grad[1] + d[2] * grad[2];
                let phi = (p[1] / B0).atan2(p[0] / A0);
                let tint = blood_tint(p[2], phi, opts.slow_blood);
                let alb: [f64; 3] =
                    std::array::from_fn(|k| albedo(p[2], phi, opts.slow_albedo)[k] * tint[k]);
                albedo_at[i] = alb;
                fr.gamma[i] = g as f32;
                fr.z[i] = t as f32;
                let ti = (p[2] / TEXEL_MM).floor() as u32;
                let pi_ = (((phi + PI) / (2.0 * PI) * n_around) as u32).min(n_around as u32 - 1);
                fr.texel[i] = ti * 1024 + pi_;
                for k in 0..3 {
                    fr.albedo_rel[3 * i + k] = (alb[k] / BASE_ALBEDO[k]) as f32;
                }
                if g > 0.0 {
                    let theta = dc[2].clamp(-1.0, 1.0).acos().to_degrees();
                    let light = opts.power * cone_profile(theta) / (t * t);
                    let (diff, spec) = brdf_cos(g);
                    for k in 0..3 {
                        rad[k] = light * (alb[k] * diff + spec) + amb_irr * alb[k] / PI;
                    }
                }
            }
            radiance[i] = rad;
        }
    }
    let lum = |c: &[f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let hits = fr.z.iter().filter(|&&z| z > 0.0).count().max(1);
    let mean_direct = radiance.iter().map(lum).sum::<f64>() / hits as f64;
    for i in 0..n {
        for k in 0..3 {
            let inter = opts.interreflection * mean_direct * albedo_at[i][k] / 0.3;
            let v = view.gain * (radiance[i][k] + inter);
            let sigma = (0.0004 * v + 0.002f64.powi(2)).sqrt();
            let noisy = (v + sigma * rng.normal()).clamp(0.0, 1.0);
            let code = (srgb_encode(noisy) * 255.0).round() / 255.0;
            fr.rgb[3 * i + k] = srgb_decode(code) as f32;
        }
    }
    fr
}
