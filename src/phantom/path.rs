//! Camera paths through the lumen: a smoothed centreline from the upper trachea through a main
//! bronchus into a lobar bronchus, with a bronchoscopist's wobble (lateral offsets, view
//! jitter of a few degrees, slow roll), and novel views off that path.
//!
//! Every pose is checked against a signed distance to the lumen wall (negative inside) and
//! pulled toward the centreline until it keeps `min_clearance_mm` of air around the lens.

use super::anatomy::AirwayTree;
use crate::math::{Affine, Point3, Vector3};
use crate::mesh::GeometryError;
use crate::rng::Pcg32;
use crate::{Error, Result};

/// How the camera moves along the centreline. Lengths in mm, angles in degrees.
#[derive(Clone, Debug)]
pub struct PathOptions {
    /// Number of poses.
    pub frames: usize,
    /// Seed of the wobble.
    pub seed: u64,
    /// Lateral offset amplitude as a fraction of the free depth at the centreline.
    pub lateral_fraction: f64,
    /// Amplitude of the smooth view-direction jitter (degrees).
    pub jitter_deg: f64,
    /// Amplitude of the slow roll (degrees).
    pub roll_deg: f64,
    /// Smallest allowed distance from the camera centre to the lumen wall (mm).
    pub min_clearance_mm: f64,
    /// The camera looks at the centreline point this far ahead (mm).
    pub look_ahead_mm: f64,
    /// Gaussian smoothing of the centreline (mm, standard deviation along the arc).
    pub smoothing_mm: f64,
}

impl Default for PathOptions {
    fn default() -> Self {
        PathOptions {
            frames: 80,
            seed: 1,
            lateral_fraction: 0.3,
            jitter_deg: 4.0,
            roll_deg: 20.0,
            min_clearance_mm: 1.5,
            look_ahead_mm: 8.0,
            smoothing_mm: 3.0,
        }
    }
}

/// The centreline the built-in tree's path follows (world mm): the trachea from 15 mm below
/// its top to 6 mm above the carina, the right main bronchus from 6 mm in, then 75 % of its wider child (lobar).
pub fn tree_centreline(tree: &AirwayTree) -> Vec<Point3<f64>> {
    let tr = &tree.branches[0];
    let mut pts: Vec<Point3<f64>> = tr
        .centreline
        .iter()
        .zip(&tr.arc_mm)
        .filter(|(_, &s)| s >= 15.0 && s <= tr.length_mm() - 6.0)
        .map(|(p, _)| *p)
        .collect();
    // The right main bronchus: the gen-1 child leaning toward +x (RAS right).
    let main = tree
        .branches
        .iter()
        .filter(|b| b.parent == Some(0))
        .max_by(|a, b| {
            let dx = |b: &super::anatomy::Branch| b.control[3].x - b.control[0].x;
            dx(a).total_cmp(&dx(b))
        })
        .expect("the tree has main bronchi");
    // The corner at the carina is cut (6 mm either side), as a bronchoscopist steers into the
    // main bronchus before reaching the carina's ridge.
    pts.extend(
        main.centreline
            .iter()
            .zip(&main.arc_mm)
            .filter(|(_, &s)| s >= 6.0)
            .map(|(p, _)| *p),
    );
    if let Some(lobar) = tree
        .branches
        .iter()
        .filter(|b| b.parent == Some(main.id))
        .max_by(|a, b| a.radius_start_mm.total_cmp(&b.radius_start_mm))
    {
        let end = 0.75 * lobar.length_mm();
        pts.extend(
            lobar
                .centreline
                .iter()
                .zip(&lobar.arc_mm)
                .skip(1)
                .filter(|(_, &s)| s <= end)
                .map(|(p, _)| *p),
        );
    }
    pts
}

/// A polyline resampled at a fixed arc step and smoothed: positions and arc lengths (mm).
#[derive(Clone, Debug)]
pub struct SmoothPath {
    /// Points every `step` mm (world mm).
    pub points: Vec<Point3<f64>>,
    /// Arc-length step between points (mm).
    pub step: f64,
}

impl SmoothPath {
    /// Resample `polyline` every `step` mm and smooth it with a Gaussian of `sigma` mm;
    /// the ends are padded by point reflection so straight ends stay straight.
    pub fn new(polyline: &[Point3<f64>], step: f64, sigma: f64) -> Result<Self> {
        let raw = resample(polyline, step);
        if raw.len() < 4 {
            return Err(GeometryError::Degenerate {
                stage: "camera path",
                message: format!("centreline too short ({} points at {step} mm)", raw.len()),
            }
            .into());
        }
        let r = (3.0 * sigma / step).ceil() as isize;
        let w: Vec<f64> = (-r..=r)
            .map(|i| (-(i as f64 * step).powi(2) / (2.0 * sigma * sigma).max(1e-12)).exp())
            .collect();
        let n = raw.len() as isize;
        let at = |i: isize| -> Vector3<f64> {
            if i < 0 {
                raw[0].coords * 2.0 - raw[(-i).min(n - 1) as usize].coords
            } else if i >= n {
                raw[(n - 1) as usize].coords * 2.0 - raw[(2 * (n - 1) - i).max(0) as usize].coords
            } else {
                raw[i as usize].coords
            }
        };
        let points = (0..n)
            .map(|i| {
                let mut acc = Vector3::zeros();
                let mut ws = 0.0;
                for (k, wk) in w.iter().enumerate() {
                    acc += at(i + k as isize - r) * *wk;
                    ws += wk;
                }
                Point3::from(acc / ws)
            })
            .collect();
        Ok(SmoothPath { points, step })
    }

    /// Total length (mm).
    pub fn length(&self) -> f64 {
        (self.points.len() - 1) as f64 * self.step
    }

    /// Point at arc length `s` (mm), clamped to the ends, linear between samples.
    pub fn at(&self, s: f64) -> Point3<f64> {
        let x = (s / self.step).clamp(0.0, (self.points.len() - 1) as f64);
        let i = (x.floor() as usize).min(self.points.len() - 2);
        let t = x - i as f64;
        self.points[i] + (self.points[i + 1] - self.points[i]) * t
    }

    /// Unit tangent at arc length `s`.
    pub fn tangent(&self, s: f64) -> Vector3<f64> {
        let h = 2.0 * self.step;
        let (a, b) = (self.at(s - h), self.at(s + h));
        (b - a).try_normalize(1e-12).unwrap_or_else(Vector3::z)
    }
}

/// Resample a polyline at a fixed arc-length step (mm).
fn resample(poly: &[Point3<f64>], step: f64) -> Vec<Point3<f64>> {
    let mut out = Vec::new();
    if poly.is_empty() {
        return out;
    }
    out.push(poly[0]);
    let mut carry = 0.0;
    for seg in poly.windows(2) {
        let d = seg[1] - seg[0];
        let len = d.norm();
        let mut s = step - carry;
        while s <= len {
            out.push(seg[0] + d * (s / len));
            s += step;
        }
        carry = len - (s - step);
    }
    out
}

/// Sum of three seeded sinusoids of arc length (periods 12–45 mm), amplitude about 1.
struct Wobble {
    waves: Vec<(f64, f64)>,
}

impl Wobble {
    fn new(rng: &mut Pcg32) -> Self {
        let waves = (0..3)
            .map(|_| {
                (
                    std::f64::consts::TAU / rng.range(12.0, 45.0),
                    rng.range(0.0, std::f64::consts::TAU),
                )
            })
            .collect();
        Wobble { waves }
    }
    fn at(&self, s: f64) -> f64 {
        self.waves
            .iter()
            .map(|(k, ph)| (k * s + ph).sin())
            .sum::<f64>()
            / 3f64.sqrt()
    }
}

/// Camera→world pose with optical axis `forward`, image "down" as close as possible to
/// `down`, rolled by `roll` radians about the axis, centred at `c`.
pub fn look_pose(
    c: &Point3<f64>,
    forward: &Vector3<f64>,
    down: &Vector3<f64>,
    roll: f64,
) -> Affine {
    let z = forward.normalize();
    let mut y = down - z * down.dot(&z);
    if y.norm() < 1e-6 {
        y = any_perp(&z);
    }
    let y0 = y.normalize();
    let x0 = y0.cross(&z);
    let (s, co) = roll.sin_cos();
    let x = x0 * co + y0 * s;
    let y = z.cross(&x);
    let mut m = Affine::identity();
    for r in 0..3 {
        m[(r, 0)] = x[r];
        m[(r, 1)] = y[r];
        m[(r, 2)] = z[r];
        m[(r, 3)] = c[r];
    }
    m
}

fn any_perp(d: &Vector3<f64>) -> Vector3<f64> {
    let a = if d.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    d.cross(&a).normalize()
}

/// Pull `c` toward `centre` until `sdf(c) <= -clearance` (halving the offset up to 8 times).
fn keep_inside(
    centre: &Point3<f64>,
    offset: Vector3<f64>,
    clearance: f64,
    sdf: &dyn Fn(&Point3<f64>) -> f64,
) -> Point3<f64> {
    let mut o = offset;
    for _ in 0..8 {
        let c = centre + o;
        if sdf(&c) <= -clearance {
            return c;
        }
        o *= 0.5;
    }
    *centre
}

/// Arc length (mm) of `path` usable by cameras: up to `max_len`, and stopping 1 mm before the
/// first point with less than the clearance (plus 0.25 mm) to the wall (narrow distal ends).
fn usable_length(
    path: &SmoothPath,
    sdf: &dyn Fn(&Point3<f64>) -> f64,
    clearance: f64,
    max_len: f64,
) -> Result<f64> {
    let mut len = max_len;
    for (k, p) in path.points.iter().enumerate() {
        if -sdf(p) < clearance + 0.25 {
            len = len.min(k as f64 * path.step - 1.0);
            break;
        }
    }
    if len < 10.0 {
        return Err(GeometryError::Degenerate {
            stage: "camera path",
            message: format!(
                "only {len:.1} mm of the centreline keep {clearance} mm from the wall"
            ),
        }
        .into());
    }
    Ok(len)
}

/// Training poses along `path`: equal arc steps from its start to `look_ahead_mm` before its
/// end (or where the lumen gets too narrow), with wobble; `sdf(p)` is the signed distance (mm) to the wall, negative inside.
/// Fails when a centreline point itself lacks the clearance.
pub fn camera_path(
    path: &SmoothPath,
    sdf: &dyn Fn(&Point3<f64>) -> f64,
    opts: &PathOptions,
) -> Result<Vec<Affine>> {
    if opts.frames == 0 {
        return Err(Error::BadOptions {
            stage: "camera path",
            message: "need at least one frame".into(),
        });
    }
    let mut rng = Pcg32::new(opts.seed, 0x9A7);
    let (w1, w2, w3, w4, w5) = (
        Wobble::new(&mut rng),
        Wobble::new(&mut rng),
        Wobble::new(&mut rng),
        Wobble::new(&mut rng),
        Wobble::new(&mut rng),
    );
    let len = usable_length(
        path,
        sdf,
        opts.min_clearance_mm,
        path.length() - 0.5 * opts.look_ahead_mm,
    )?;
    // Image "down" starts posterior (-y RAS) and is parallel-transported along the path.
    let mut down = Vector3::new(0.0, -1.0, 0.0);
    let mut poses = Vec::with_capacity(opts.frames);
    for i in 0..opts.frames {
        let s = if opts.frames == 1 {
            0.0
        } else {
            len * i as f64 / (opts.frames - 1) as f64
        };
        let c0 = path.at(s);
        let depth = -sdf(&c0);
        if depth < opts.min_clearance_mm {
            return Err(GeometryError::Degenerate {
                stage: "camera path",
                message: format!(
                    "centreline point {i} at ({:.1}, {:.1}, {:.1}) mm is only {depth:.2} mm from the wall",
                    c0.x, c0.y, c0.z
                ),
            }
            .into());
        }
        let t = path.tangent(s);
        down = (down - t * down.dot(&t))
            .try_normalize(1e-9)
            .unwrap_or_else(|| any_perp(&t));
        let e1 = t.cross(&down);
        let free = depth - opts.min_clearance_mm;
        let off = (e1 * w1.at(s) + down * w2.at(s)) * (opts.lateral_fraction * free);
        let c = keep_inside(&c0, off, opts.min_clearance_mm, sdf);
        let ahead = path.at(s + opts.look_ahead_mm);
        let mut f = (ahead - c).try_normalize(1e-9).unwrap_or(t);
        // Smooth jitter plus a little per-frame shake.
        let j = opts.jitter_deg.to_radians();
        let yaw = j * (w3.at(s) + 0.15 * rng.normal());
        let pitch = j * (w4.at(s) + 0.15 * rng.normal());
        f = (f + e1 * yaw.tan() + down * pitch.tan()).normalize();
        let roll = opts.roll_deg.to_radians() * w5.at(0.5 * s);
        poses.push(look_pose(&c, &f, &down, roll));
    }
    Ok(poses)
}

/// `count` novel poses off the training path: between training positions, offset laterally by
/// half the free depth in a different direction each, looking 10–35° away from the path
/// direction, with their own roll.
pub fn novel_views(
    path: &SmoothPath,
    sdf: &dyn Fn(&Point3<f64>) -> f64,
    count: usize,
    opts: &PathOptions,
) -> Result<Vec<Affine>> {
    let mut rng = Pcg32::new(opts.seed, 0x7E5);
    let len = usable_length(
        path,
        sdf,
        opts.min_clearance_mm,
        path.length() - opts.look_ahead_mm,
    )?;
    let mut down = Vector3::new(0.0, -1.0, 0.0);
    let mut views = Vec::with_capacity(count);
    for k in 0..count {
        let s = len * (k as f64 + 0.5) / count as f64;
        let c0 = path.at(s);
        let depth = -sdf(&c0);
        if depth < opts.min_clearance_mm {
            return Err(GeometryError::Degenerate {
                stage: "novel views",
                message: format!(
                    "centreline point at ({:.1}, {:.1}, {:.1}) mm is only {depth:.2} mm from the wall",
                    c0.x, c0.y, c0.z
                ),
            }
            .into());
        }
        let t = path.tangent(s);
        down = (down - t * down.dot(&t))
            .try_normalize(1e-9)
            .unwrap_or_else(|| any_perp(&t));
        let e1 = t.cross(&down);
        let phi = k as f64 * 2.399_963 + rng.range(0.0, 0.5);
        let dir = e1 * phi.cos() + down * phi.sin();
        let c = keep_inside(
            &c0,
            dir * (0.5 * (depth - opts.min_clearance_mm)),
            opts.min_clearance_mm,
            sdf,
        );
        let tilt = rng.range(10.0, 35.0).to_radians();
        let az = rng.range(0.0, std::f64::consts::TAU);
        let f = (t * tilt.cos() + (e1 * az.cos() + down * az.sin()) * tilt.sin()).normalize();
        let roll = rng.range(-60.0, 60.0).to_radians();
        views.push(look_pose(&c, &f, &down, roll));
    }
    Ok(views)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::anatomy::TreeOptions;
    use crate::rng::Pcg32;

    #[test]
    fn tree_path_stays_inside_and_moves_down_the_airway() {
        let tree = AirwayTree::new(&TreeOptions::default());
        let path = SmoothPath::new(&tree_centreline(&tree), 0.5, 3.0).unwrap();
        assert!(path.length() > 100.0, "path length {}", path.length());
        let sdf = |p: &Point3<f64>| tree.lumen_sdf(*p);
        let opts = PathOptions::default();
        let poses = camera_path(&path, &sdf, &opts).unwrap();
        assert_eq!(poses.len(), 80);
        let mut max_angle: f64 = 0.0;
        for (i, m) in poses.iter().enumerate() {
            let c = Point3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
            assert!(
                tree.lumen_sdf(c) <= -1.5,
                "pose {i}: sdf {}",
                tree.lumen_sdf(c)
            );
            // Rotation is orthonormal with determinant +1.
            let r = m.fixed_view::<3, 3>(0, 0).into_owned();
            assert!((r.transpose() * r - crate::math::Matrix3::identity()).norm() < 1e-9);
            assert!((r.determinant() - 1.0).abs() < 1e-9);
            if i > 0 {
                let z0 = poses[i - 1].fixed_view::<3, 1>(0, 2).into_owned();
                let z1 = m.fixed_view::<3, 1>(0, 2).into_owned();
                max_angle = max_angle.max(z0.dot(&z1).clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
        // Smooth: no frame-to-frame turn above 20°.
        assert!(max_angle < 20.0, "largest turn {max_angle}°");
        // Starts high in the trachea, ends below the carina on the right (+x).
        let first = poses[0].fixed_view::<3, 1>(0, 3).into_owned();
        let last = poses[79].fixed_view::<3, 1>(0, 3).into_owned();
        assert!(
            first.z > 70.0 && last.z < -10.0 && last.x > 5.0,
            "{first:?} {last:?}"
        );
        // The wobble moves off the smoothed centreline by up to a few mm, not more.
        let mut max_off: f64 = 0.0;
        for m in &poses {
            let c = Point3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
            let d = path
                .points
                .iter()
                .map(|p| (p - c).norm())
                .fold(f64::INFINITY, f64::min);
            max_off = max_off.max(d);
        }
        assert!(
            max_off > 0.3 && max_off < 4.0,
            "largest offset {max_off} mm"
        );
        let views = novel_views(&path, &sdf, 8, &opts).unwrap();
        for v in &views {
            let c = Point3::new(v[(0, 3)], v[(1, 3)], v[(2, 3)]);
            assert!(tree.lumen_sdf(c) <= -1.5);
        }
    }

    #[test]
    fn smoothing_keeps_a_straight_line() {
        let mut rng = Pcg32::new(1, 2);
        let pts: Vec<Point3<f64>> = (0..40)
            .map(|i| Point3::new(i as f64 * 2.0 + rng.range(0.0, 0.01), 1.0, -2.0))
            .collect();
        let p = SmoothPath::new(&pts, 0.5, 3.0).unwrap();
        assert!((p.length() - 78.0).abs() < 0.6, "{}", p.length());
        for q in &p.points {
            assert!((q.y - 1.0).abs() < 1e-9 && (q.z + 2.0).abs() < 1e-9);
        }
        assert!((p.at(10.0).x - 10.0).abs() < 0.1);
    }
}
