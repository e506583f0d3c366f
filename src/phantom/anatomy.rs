//! The phantom's airway tree as data: tapered, gently curved tubes joined smoothly.
//!
//! Each branch is a cubic Bézier centreline with a radius that tapers linearly along its arc
//! length; the trachea (and, weaker, the main bronchi) carry a periodic cartilage-ring
//! relief. The lumen is the smooth union (polynomial smooth-min) of the branch tube SDFs, so
//! junctions are filleted like real carinas. The same data drives the CT voxelisation, the
//! "every branch found" truth and, later, camera paths along the centrelines.
//!
//! World coordinates are RAS+ mm (+x patient right, +y anterior, +z superior) with the
//! carina at the origin.

use crate::math::{Point3, Vector3};
use crate::rng::Pcg32;

pub use super::branch::Branch;

/// World direction of the patient's right in RAS+.
pub const RIGHT: Vector3<f64> = Vector3::new(1.0, 0.0, 0.0);

/// How the tree is generated. Every length is in mm.
#[derive(Clone, Debug)]
pub struct TreeOptions {
    /// Seed of the jitter in angles, lengths and split planes (same seed, same tree).
    pub seed: u64,
    /// Deepest generation (0 = trachea only; default 4: trachea, main, lobar, segmental,
    /// subsegmental, 31 branches).
    pub generations: u32,
    /// Trachea inner radius at its top (mm).
    pub trachea_radius_mm: f64,
    /// Trachea length from the top to the carina (mm).
    pub trachea_length_mm: f64,
    /// Cartilage-ring relief on the trachea: amplitude and period (mm).
    pub ring_amplitude_mm: f64,
    /// Cartilage-ring period (mm).
    pub ring_period_mm: f64,
    /// Width of the smooth-min fillet at junctions (mm).
    pub junction_smoothing_mm: f64,
    /// The trachea's posterior (membranous) wall, where the C-shaped cartilage rings are
    /// open: a flat wall this fraction of the radius behind the axis (`None`: a round
    /// trachea). A round straight tube lets the camera turn about its axis without changing
    /// what it sees, so only the far carina fixes the video's roll there.
    pub trachea_posterior_wall: Option<f64>,
}

impl Default for TreeOptions {
    fn default() -> Self {
        TreeOptions {
            seed: 1,
            generations: 4,
            trachea_radius_mm: 8.5,
            trachea_length_mm: 100.0,
            ring_amplitude_mm: 0.3,
            ring_period_mm: 4.0,
            junction_smoothing_mm: 1.5,
            trachea_posterior_wall: None,
        }
    }
}

/// The phantom airway: its branches and the smooth-union lumen SDF.
#[derive(Clone, Debug)]
pub struct AirwayTree {
    /// Branches, parents before children; branch 0 is the trachea.
    pub branches: Vec<Branch>,
    /// Smooth-min width at junctions (mm).
    pub junction_smoothing_mm: f64,
    /// The seed the tree was generated with.
    pub seed: u64,
}

/// Polynomial smooth minimum (Quilez): equals `min(a, b)` when |a - b| >= k, and is at most
/// k/4 below it.
#[inline]
pub fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    if k <= 0.0 {
        return a.min(b);
    }
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

/// Lumen radius (mm) at the start of a branch of generation `g` (major child; minor children
/// get 80 %). Main bronchi are set apart (right wider than left).
fn generation_radius(g: u32) -> f64 {
    match g {
        0 => 8.5,
        1 => 6.0,
        2 => 4.2,
        3 => 3.0,
        4 => 2.0,
        g => 2.0 * 0.75f64.powi(g as i32 - 4),
    }
}

/// A unit vector perpendicular to `d`.
fn any_perpendicular(d: &Vector3<f64>) -> Vector3<f64> {
    let a = if d.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    d.cross(&a).normalize()
}

/// Rotate `v` about the unit axis `k` by `angle` (radians), Rodrigues' formula.
fn rotate(v: &Vector3<f64>, k: &Vector3<f64>, angle: f64) -> Vector3<f64> {
    let (s, c) = angle.sin_cos();
    v * c + k.cross(v) * s + k * (k.dot(v) * (1.0 - c))
}

struct Spec {
    parent: Option<usize>,
    generation: u32,
    start: Point3<f64>,
    d_start: Vector3<f64>,
    d_end: Vector3<f64>,
    length: f64,
    r0: f64,
    r1: f64,
    ring: f64,
    posterior_wall: Option<f64>,
    split_axis: Vector3<f64>,
}

impl AirwayTree {
    /// Generate the tree: trachea along -z ending at the carina (origin), main bronchi in the
    /// coronal plane (right ~25° off vertical and wider, left ~45° and narrower), then each
    /// generation splits into a major (15–30°) and a minor (35–60°) child in a plane turned
    /// ~90° from the parent's. Draws are retried until non-adjacent tubes keep clear of each
    /// other (walls included).
    pub fn new(opts: &TreeOptions) -> Self {
        let mut rng = Pcg32::new(opts.seed, 0xA1);
        let mut last = None;
        for _attempt in 0..200 {
            let tree = Self::draw(opts, &mut rng);
            if tree.clearance_ok(5.0) {
                return tree;
            }
            last = Some(tree);
        }
        last.expect("at least one draw")
    }

    fn draw(opts: &TreeOptions, rng: &mut Pcg32) -> Self {
        let l = opts.trachea_length_mm;
        let mut specs = vec![Spec {
            parent: None,
            generation: 0,
            // The trachea runs slightly backwards (posterior, -y) as it descends.
            start: Point3::new(0.0, 0.08 * l, l),
            d_start: Vector3::new(0.0, -0.05, -1.0).normalize(),
            d_end: Vector3::new(0.0, -0.12, -1.0).normalize(),
            length: l,
            r0: opts.trachea_radius_mm,
            r1: opts.trachea_radius_mm * 0.94,
            ring: opts.ring_amplitude_mm,
            posterior_wall: opts.trachea_posterior_wall,
            split_axis: RIGHT,
        }];
        let mut built: Vec<Branch> = Vec::new();
        let mut i = 0;
        while i < specs.len() {
            let b = make_branch(i, &specs[i], opts.ring_period_mm);
            let g = specs[i].generation;
            if g < opts.generations {
                let end = *b.centreline.last().unwrap();
                let n = b.centreline.len();
                let d = (b.centreline[n - 1] - b.centreline[n - 2]).normalize();
                let axis = specs[i].split_axis;
                let r_end = specs[i].r1;
                let children: Vec<(f64, f64, f64, f64)> = if g == 0 {
                    // (angle off the parent axis, side sign, start radius, length)
                    vec![
                        (25f64.to_radians(), 1.0, 6.5, 25.0 * rng.range(0.9, 1.1)),
                        (-45f64.to_radians(), 1.0, 5.5, 45.0 * rng.range(0.9, 1.1)),
                    ]
                } else {
                    let rg = generation_radius(g + 1).min(r_end * 0.95);
                    let major = rng.range(15.0, 30.0).to_radians();
                    let minor = -rng.range(35.0, 60.0).to_radians();
                    let len = |r: f64, rng: &mut Pcg32| 2.0 * r * rng.range(2.0, 2.8);
                    let lm = len(rg, rng);
                    let ln = len(rg * 0.8, rng);
                    vec![(major, 1.0, rg, lm), (minor, 1.0, rg * 0.8, ln)]
                };
                let perp_axis = d.cross(&axis);
                for (angle, _, r0, length) in children {
                    // Child direction: the parent axis tilted by `angle` towards `axis`.
                    let k = perp_axis
                        .try_normalize(1e-9)
                        .unwrap_or_else(|| any_perpendicular(&d));
                    let dir = rotate(&d, &k, angle).normalize();
                    let bend = rng.range(-8.0, 8.0).to_radians();
                    let d_end = rotate(&dir, &k, bend).normalize();
                    // The next split plane turns 70–110° about the child's axis.
                    let turn = rng.range(70.0, 110.0).to_radians();
                    let in_plane = (axis - dir * axis.dot(&dir))
                        .try_normalize(1e-9)
                        .unwrap_or_else(|| any_perpendicular(&dir));
                    let next_axis = rotate(&in_plane, &d_end, turn).normalize();
                    let ring = if g == 0 {
                        opts.ring_amplitude_mm * 0.5
                    } else {
                        0.0
                    };
                    specs.push(Spec {
                        parent: Some(i),
                        generation: g + 1,
                        start: end,
                        d_start: (d * 0.6 + dir).normalize(),
                        d_end,
                        length,
                        r0,
                        r1: r0 * 0.85,
                        ring,
                        posterior_wall: None,
                        split_axis: next_axis,
                    });
                }
            }
            built.push(b);
            i += 1;
        }
        AirwayTree {
            branches: built,
            junction_smoothing_mm: opts.junction_smoothing_mm,
            seed: opts.seed,
        }
    }

    /// True when every pair of branches that are neither ancestor/descendant nor siblings
    /// keeps `wall_mm` of tissue on each side between their lumens.
    fn clearance_ok(&self, wall_mm: f64) -> bool {
        let anc = |mut a: usize, b: usize| -> bool {
            while let Some(p) = self.branches[a].parent {
                if p == b {
                    return true;
                }
                a = p;
            }
            false
        };
        for a in 0..self.branches.len() {
            for b in a + 1..self.branches.len() {
                let (ba, bb) = (&self.branches[a], &self.branches[b]);
                if anc(a, b) || anc(b, a) {
                    continue;
                }
                let siblings = ba.parent == bb.parent;
                for (ia, pa) in ba.centreline.iter().enumerate() {
                    if siblings && ba.arc_mm[ia] < 0.5 * ba.length_mm() {
                        continue;
                    }
                    for (ib, pb) in bb.centreline.iter().enumerate() {
                        if siblings && bb.arc_mm[ib] < 0.5 * bb.length_mm() {
                            continue;
                        }
                        if (pa - pb).norm() < ba.radii[ia] + bb.radii[ib] + 2.0 * wall_mm {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// Signed distance (mm) from `p` (world mm) to the lumen surface: negative inside the
    /// lumen. The smooth union of the branch tubes, exact far from junctions.
    pub fn lumen_sdf(&self, p: Point3<f64>) -> f64 {
        self.sdf_among(&p, 0..self.branches.len())
    }

    /// [`Self::lumen_sdf`] over a subset of branches (e.g. from [`Self::branches_near`]);
    /// exact wherever the omitted branches are farther than the result plus the smoothing.
    pub fn sdf_among(&self, p: &Point3<f64>, ids: impl IntoIterator<Item = usize>) -> f64 {
        let k = self.junction_smoothing_mm;
        let mut acc = f64::INFINITY;
        for id in ids {
            let b = &self.branches[id];
            // A branch whose box is farther than acc + k cannot change the smooth minimum.
            if b.bbox_distance(p) > acc + k {
                continue;
            }
            let d = b.sdf(p);
            acc = if acc.is_finite() {
                smooth_min(acc, d, k)
            } else {
                d
            };
        }
        acc
    }

    /// Branches whose tube comes within `margin` mm of the box [lo, hi] (world mm).
    pub fn branches_near(&self, lo: &Point3<f64>, hi: &Point3<f64>, margin: f64) -> Vec<usize> {
        self.branches
            .iter()
            .filter(|b| {
                (0..3).all(|a| b.bbox_lo[a] - margin <= hi[a] && b.bbox_hi[a] + margin >= lo[a])
            })
            .map(|b| b.id)
            .collect()
    }

    /// World bounding box (mm) of the lumen: (min, max).
    pub fn bounds(&self) -> (Point3<f64>, Point3<f64>) {
        let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut hi = -lo;
        for b in &self.branches {
            for a in 0..3 {
                lo[a] = lo[a].min(b.bbox_lo[a]);
                hi[a] = hi[a].max(b.bbox_hi[a]);
            }
        }
        (lo, hi)
    }

    /// The carina: where the trachea ends and the main bronchi start (world mm).
    pub fn carina(&self) -> Point3<f64> {
        *self.branches[0].centreline.last().unwrap()
    }
}

/// Sample a branch's Bézier centreline (about one sample per 1.5 mm) and its radii.
fn make_branch(id: usize, s: &Spec, ring_period: f64) -> Branch {
    let p0 = s.start;
    let chord = (s.d_start + s.d_end).normalize();
    let p3 = p0 + chord * s.length;
    let p1 = p0 + s.d_start * (s.length / 3.0);
    let p2 = p3 - s.d_end * (s.length / 3.0);
    let n = ((s.length / 1.5).ceil() as usize).max(8);
    let mut centreline = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let u = 1.0 - t;
        let c = p0.coords * (u * u * u)
            + p1.coords * (3.0 * u * u * t)
            + p2.coords * (3.0 * u * t * t)
            + p3.coords * (t * t * t);
        centreline.push(Point3::from(c));
    }
    let mut arc_mm = vec![0.0];
    for i in 1..centreline.len() {
        let d = (centreline[i] - centreline[i - 1]).norm();
        arc_mm.push(arc_mm[i - 1] + d);
    }
    let mut b = Branch {
        id,
        parent: s.parent,
        generation: s.generation,
        control: [p0, p1, p2, p3],
        centreline,
        arc_mm,
        radii: Vec::new(),
        radius_start_mm: s.r0,
        radius_end_mm: s.r1,
        ring_amplitude_mm: s.ring,
        ring_period_mm: ring_period,
        posterior_wall: s.posterior_wall,
        bbox_lo: Point3::origin(),
        bbox_hi: Point3::origin(),
    };
    b.radii = b.arc_mm.iter().map(|&a| b.radius_at(a)).collect();
    let rmax = s.r0.max(s.r1) + s.ring.abs();
    let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut hi = -lo;
    for p in &b.centreline {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a] - rmax);
            hi[a] = hi[a].max(p[a] + rmax);
        }
    }
    b.bbox_lo = lo;
    b.bbox_hi = hi;
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_tree_has_realistic_calibres_and_angles() {
        let t = AirwayTree::new(&TreeOptions::default());
        assert_eq!(t.branches.len(), 31);
        let tr = &t.branches[0];
        assert!(
            (tr.length_mm() - 100.0).abs() < 3.0,
            "trachea length {}",
            tr.length_mm()
        );
        assert!(tr.min_diameter_mm() > 15.0 && tr.min_diameter_mm() < 18.0);
        // Main bronchi: right (towards +x in RAS) ~25° off vertical and wider than the left ~45°.
        let dir = |b: &Branch| (b.control[3] - b.control[0]).normalize();
        let (r, l) = (&t.branches[1], &t.branches[2]);
        let ang = |v: Vector3<f64>| v.dot(&Vector3::new(0.0, 0.0, -1.0)).acos().to_degrees();
        assert!(dir(r).x > 0.0 && dir(l).x < 0.0);
        assert!((ang(dir(r)) - 25.0).abs() < 12.0, "right {}", ang(dir(r)));
        assert!((ang(dir(l)) - 45.0).abs() < 12.0, "left {}", ang(dir(l)));
        assert!(r.radius_start_mm > l.radius_start_mm);
        let smallest = t
            .branches
            .iter()
            .map(|b| b.min_diameter_mm())
            .fold(f64::INFINITY, f64::min);
        assert!(
            smallest > 2.0 && smallest < 3.5,
            "smallest diameter {smallest}"
        );
        // The SDF is negative on every centreline sample and positive far away.
        for b in &t.branches {
            for p in &b.centreline {
                assert!(t.lumen_sdf(*p) < 0.0);
            }
        }
        assert!(t.lumen_sdf(Point3::new(200.0, 0.0, 0.0)) > 100.0);
        // Same seed, same tree.
        let t2 = AirwayTree::new(&TreeOptions::default());
        assert_eq!(t2.branches[17].control, t.branches[17].control);
    }

    #[test]
    fn sdf_is_the_distance_to_a_straight_tube() {
        let t = AirwayTree::new(&TreeOptions {
            ring_amplitude_mm: 0.0,
            ..Default::default()
        });
        let tr = &t.branches[0];
        let mid = tr.centreline[tr.centreline.len() / 3];
        let s = tr.arc_mm[tr.centreline.len() / 3];
        let p = mid + Vector3::new(3.0, 0.0, 0.0);
        let d = t.lumen_sdf(p);
        assert!((d - (3.0 - tr.radius_at(s))).abs() < 0.05, "{d}");
    }

    #[test]
    fn a_posterior_wall_flattens_the_back_of_the_trachea_alone() {
        let opts = |wall| TreeOptions {
            ring_amplitude_mm: 0.0,
            trachea_posterior_wall: wall,
            ..Default::default()
        };
        let (round, flat) = (
            AirwayTree::new(&opts(None)),
            AirwayTree::new(&opts(Some(0.7))),
        );
        let tr = &flat.branches[0];
        let k = tr.centreline.len() / 3;
        let (mid, axis) = (tr.centreline[k], tr.centreline[k + 1] - tr.centreline[k]);
        let r = tr.radius_at(tr.arc_mm[k]);
        let back = Vector3::new(0.0, -1.0, 0.0);
        let back = (back - axis * back.dot(&axis) / axis.norm_squared()).normalize();
        // The back wall is 0.7 r behind the axis; the front and the sides are where they were.
        let on_back = flat.lumen_sdf(mid + back * (0.7 * r));
        assert!(on_back.abs() < 0.05, "{on_back}");
        let behind = flat.lumen_sdf(mid + back * (0.9 * r));
        assert!((behind - 0.2 * r).abs() < 0.05, "{behind}");
        for dir in [-back, back.cross(&axis.normalize())] {
            let (a, b) = (
                round.lumen_sdf(mid + dir * r),
                flat.lumen_sdf(mid + dir * r),
            );
            assert!(a.abs() < 0.05 && (a - b).abs() < 1e-9, "{a} {b}");
        }
        // The bronchi stay round.
        let main = &flat.branches[1];
        let m = main.centreline[main.centreline.len() / 2];
        assert_eq!(flat.lumen_sdf(m), round.lumen_sdf(m));
    }
}
