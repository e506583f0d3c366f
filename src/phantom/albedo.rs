//! The phantom's mucosa albedo: a deterministic procedural reflectance defined in 3-D world
//! space, evaluated only on the lumen surface.
//!
//! Layers, from bottom to top: a pinkish-red base (linear RGB about (0.55, 0.25, 0.20)) with
//! low-frequency brightness and hue variation (value-noise fBm over ~8 mm), pale patches
//! (thresholded fBm over ~6 mm blended toward a whitish pink), and a darker branching vessel
//! network drawn along the cell borders of two Worley (cellular) noises — coarse vessels
//! ~0.5 mm wide on ~5 mm cells, fine capillaries ~0.3 mm on ~2 mm cells — whose presence is
//! modulated by another noise so the network thins out and breaks up like real vasculature.
//! Defined on 3-D points rather than a UV chart, so it has no seams and needs no atlas.

use crate::math::Point3;

/// A deterministic procedural mucosa albedo (linear RGB in [0, 1]); see the module docs.
#[derive(Clone, Debug)]
pub struct MucosaAlbedo {
    /// Seed of every noise layer.
    pub seed: u64,
    /// Base mucosa colour (linear RGB).
    pub base: [f32; 3],
    /// Vessel colour (linear RGB) the base is blended toward inside a vessel.
    pub vessel: [f32; 3],
    /// Pale patch colour (linear RGB).
    pub pale: [f32; 3],
    /// Coarse vessel network: Worley cell size (mm) and line width (mm).
    pub coarse_cell_mm: f64,
    /// Coarse vessel line width (mm).
    pub coarse_width_mm: f64,
    /// Fine vessel network: Worley cell size (mm).
    pub fine_cell_mm: f64,
    /// Fine vessel line width (mm).
    pub fine_width_mm: f64,
    /// Length scale (mm) of the low-frequency colour variation.
    pub variation_mm: f64,
    /// Relative amplitude of the brightness variation (0.15 = ±15 %).
    pub variation_amplitude: f64,
}

impl MucosaAlbedo {
    /// The default mucosa for `seed`.
    pub fn new(seed: u64) -> Self {
        MucosaAlbedo {
            seed,
            base: [0.55, 0.25, 0.20],
            vessel: [0.30, 0.05, 0.06],
            pale: [0.72, 0.52, 0.46],
            coarse_cell_mm: 5.0,
            coarse_width_mm: 0.5,
            fine_cell_mm: 2.0,
            fine_width_mm: 0.3,
            variation_mm: 8.0,
            variation_amplitude: 0.15,
        }
    }

    /// Albedo (linear RGB, each channel in [0, 1]) at the surface point `p` (world mm).
    pub fn eval(&self, p: Point3<f64>) -> [f32; 3] {
        let s = self.seed;
        let q = [p.x, p.y, p.z];
        // Low-frequency variation: brightness and a red/yellow hue shift.
        let v1 = fbm(&q, 1.0 / self.variation_mm, s ^ 0x11, 3);
        let v2 = fbm(&q, 1.0 / (1.6 * self.variation_mm), s ^ 0x22, 2);
        let bright = 1.0 + self.variation_amplitude * 2.0 * v1;
        let hue = 0.12 * v2;
        let mut c = [
            self.base[0] as f64 * bright * (1.0 + 0.5 * hue),
            self.base[1] as f64 * bright * (1.0 - hue),
            self.base[2] as f64 * bright * (1.0 - 0.6 * hue),
        ];
        // Pale patches: where a second fBm exceeds a threshold, with soft edges (~1 mm).
        let pn = fbm(&q, 1.0 / 6.0, s ^ 0x33, 3);
        let pale = smoothstep(0.22, 0.34, pn) * 0.75;
        for (ch, pc) in c.iter_mut().zip(self.pale) {
            *ch += (pc as f64 - *ch) * pale;
        }
        // Vessels: borders of Worley cells, warped so they meander; density modulated.
        let warp = [
            q[0] + 1.2 * fbm(&q, 0.25, s ^ 0x44, 2),
            q[1] + 1.2 * fbm(&q, 0.25, s ^ 0x55, 2),
            q[2] + 1.2 * fbm(&q, 0.25, s ^ 0x66, 2),
        ];
        let density = fbm(&q, 1.0 / 10.0, s ^ 0x77, 2);
        let coarse_on = smoothstep(-0.25, 0.05, density);
        let fine_on = smoothstep(-0.05, 0.25, density) * 0.7;
        let mut v = 0.0;
        if coarse_on > 0.0 {
            let d = cell_border_distance(&warp, self.coarse_cell_mm, s ^ 0x88);
            v = line_profile(d, self.coarse_width_mm) * coarse_on;
        }
        if fine_on > 0.0 && v < 0.99 {
            let d = cell_border_distance(&warp, self.fine_cell_mm, s ^ 0x99);
            v = v.max(line_profile(d, self.fine_width_mm) * fine_on * 0.75);
        }
        for (ch, vc) in c.iter_mut().zip(self.vessel) {
            *ch += (vc as f64 - *ch) * v;
        }
        c.map(|x| x.clamp(0.0, 1.0) as f32)
    }
}

/// 1 on the line's axis falling smoothly to 0 at half the width beyond the edge.
#[inline]
fn line_profile(d: f64, width: f64) -> f64 {
    1.0 - smoothstep(0.5 * width * 0.6, 0.5 * width * 1.4, d)
}

#[inline]
fn smoothstep(a: f64, b: f64, x: f64) -> f64 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// 64-bit integer hash of a lattice cell and a seed (SplitMix64-style finaliser).
#[inline]
fn hash3(i: i64, j: i64, k: i64, seed: u64) -> u64 {
    let h = seed
        ^ (i as u64).wrapping_mul(0x9E3779B97F4A7C15)
        ^ (j as u64).wrapping_mul(0xC2B2AE3D27D4EB4F)
        ^ (k as u64).wrapping_mul(0x165667B19E3779F9);
    crate::rng::mix64(h)
}

/// Uniform in [0, 1) from 21 bits of `h` starting at bit `shift`.
#[inline]
fn unit(h: u64, shift: u32) -> f64 {
    ((h >> shift) & 0x1F_FFFF) as f64 / (1u64 << 21) as f64
}

/// Trilinear value noise in [-1, 1] with quintic fade, at frequency 1 per lattice cell.
fn value_noise(p: &[f64; 3], seed: u64) -> f64 {
    let f = p.map(f64::floor);
    let i = f.map(|x| x as i64);
    let t = [0, 1, 2].map(|a| {
        let x = p[a] - f[a];
        x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
    });
    let mut acc = 0.0;
    for c in 0..8 {
        let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
        let w = (if dx == 1 { t[0] } else { 1.0 - t[0] })
            * (if dy == 1 { t[1] } else { 1.0 - t[1] })
            * (if dz == 1 { t[2] } else { 1.0 - t[2] });
        let h = hash3(i[0] + dx, i[1] + dy, i[2] + dz, seed);
        acc += w * (2.0 * unit(h, 0) - 1.0);
    }
    acc
}

/// Fractal sum of `octaves` value noises starting at `freq` (1/mm), roughly in [-1, 1].
fn fbm(p: &[f64; 3], freq: f64, seed: u64, octaves: u32) -> f64 {
    let (mut f, mut a, mut sum, mut norm) = (freq, 1.0, 0.0, 0.0);
    for o in 0..octaves {
        // Each octave is rotated off the lattice axes so axis-aligned artefacts do not stack.
        let q = [
            p[0] * f + 0.31 * o as f64,
            (0.8 * p[1] + 0.6 * p[2]) * f,
            (-0.6 * p[1] + 0.8 * p[2]) * f + 0.17 * o as f64,
        ];
        sum += a * value_noise(&q, seed.wrapping_add(o as u64 * 0x1000193));
        norm += a;
        f *= 2.03;
        a *= 0.5;
    }
    sum / norm
}

/// Distance (mm) from `p` to the nearest border between Worley cells of size `cell` (mm):
/// the bisector plane between the nearest and second-nearest feature points.
fn cell_border_distance(p: &[f64; 3], cell: f64, seed: u64) -> f64 {
    let q = p.map(|x| x / cell);
    let base = q.map(|x| x.floor() as i64);
    let mut best = [(f64::INFINITY, [0.0; 3]); 2];
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let c = [base[0] + dx, base[1] + dy, base[2] + dz];
                let h = hash3(c[0], c[1], c[2], seed);
                let fp = [
                    c[0] as f64 + unit(h, 0),
                    c[1] as f64 + unit(h, 21),
                    c[2] as f64 + unit(h, 42),
                ];
                let d2 = (fp[0] - q[0]).powi(2) + (fp[1] - q[1]).powi(2) + (fp[2] - q[2]).powi(2);
                if d2 < best[0].0 {
                    best[1] = best[0];
                    best[0] = (d2, fp);
                } else if d2 < best[1].0 {
                    best[1] = (d2, fp);
                }
            }
        }
    }
    let (a, b) = (best[0].1, best[1].1);
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let len = (ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2])
        .sqrt()
        .max(1e-9);
    // (|p-b|² - |p-a|²) / (2 |b-a|) is the distance to the bisector plane.
    (best[1].0 - best[0].0) / (2.0 * len) * cell
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Pcg32;

    #[test]
    fn albedo_is_deterministic_pinkish_with_vessels_and_pale_patches() {
        let a = MucosaAlbedo::new(3);
        let b = MucosaAlbedo::new(3);
        let c = MucosaAlbedo::new(4);
        let mut rng = Pcg32::new(9, 1);
        let n = 20000;
        let (mut mean, mut dark, mut pale, mut differ) = ([0.0f64; 3], 0, 0, 0);
        for _ in 0..n {
            let p = Point3::new(
                rng.range(-60.0, 60.0),
                rng.range(-60.0, 60.0),
                rng.range(-60.0, 60.0),
            );
            let (x, y) = (a.eval(p), b.eval(p));
            assert_eq!(x, y);
            if c.eval(p) != x {
                differ += 1;
            }
            for ch in 0..3 {
                assert!((0.0..=1.0).contains(&x[ch]));
                mean[ch] += x[ch] as f64 / n as f64;
            }
            // Vessels: red well below the base; pale: green well above it.
            if x[0] < 0.40 {
                dark += 1;
            }
            if x[1] > 0.38 {
                pale += 1;
            }
        }
        // Pinkish red on average: R > G > B-ish, close to the base colour.
        assert!(mean[0] > 0.45 && mean[0] < 0.62, "mean {mean:?}");
        assert!(mean[1] > 0.18 && mean[1] < 0.33, "mean {mean:?}");
        assert!(mean[0] > 1.6 * mean[1], "mean {mean:?}");
        // Vessels cover a few to ~25 % of the surface, pale patches a few %.
        let (fd, fp) = (dark as f64 / n as f64, pale as f64 / n as f64);
        assert!(fd > 0.03 && fd < 0.30, "vessel fraction {fd}");
        assert!(fp > 0.01 && fp < 0.25, "pale fraction {fp}");
        assert!(
            differ > n * 9 / 10,
            "another seed changes the albedo: {differ}"
        );
    }

    #[test]
    fn vessel_lines_have_the_requested_width() {
        // Along a straight line, runs of dark (vessel) samples are ~0.2–1 mm long.
        let a = MucosaAlbedo::new(5);
        let step = 0.02;
        let mut runs = Vec::new();
        let mut run = 0usize;
        for i in 0..200_000 {
            let p = Point3::new(i as f64 * step, 3.3, -7.1);
            let v = a.eval(p)[0] < 0.38;
            if v {
                run += 1;
            } else if run > 0 {
                runs.push(run as f64 * step);
                run = 0;
            }
        }
        runs.sort_by(f64::total_cmp);
        assert!(runs.len() > 50, "{} vessel crossings", runs.len());
        let median = runs[runs.len() / 2];
        assert!(median > 0.15 && median < 1.2, "median crossing {median} mm");
    }
}
