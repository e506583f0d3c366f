//! The phantom's albedo baked onto its truth mesh, for long HD videos (issue 21).
//!
//! The procedural mucosa ([`MucosaAlbedo`]) costs about a microsecond per ray hit: 150 lattice
//! hashes of fBm and Worley noise. A minute of 1280 x 720 video is 1.7 billion hits, hours of
//! rendering. Baked, it is a lookup: every triangle holds the procedural albedo at the points
//! of a regular barycentric lattice (`n` steps along each edge, one `n` for the whole mesh,
//! the longest edge over `n` no wider than the spacing asked), and a hit interpolates linearly
//! between the three lattice points around it.
//!
//! The baked albedo is a function of its own, not an approximation the truth must excuse: the
//! case's frames, its truth views (radiance and `_albedo.png`) and `albedo_vertices.ply` all
//! come from it, so the truth stays exact. It is continuous across triangles: a shared edge is
//! sampled at the same points by both triangles (the same barycentric weights of the same two
//! vertices, summed in an order-independent way), so both see the same values there.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::albedo::MucosaAlbedo;
use crate::math::Point3;
use crate::raycast::Scene;

/// How the phantom evaluates its albedo (truth.json `albedo`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum AlbedoSampling {
    /// The procedural function at every ray hit.
    Procedural,
    /// Baked on the truth mesh with lattice points at most `spacing_mm` apart.
    Baked {
        /// Largest distance (mm) between neighbouring lattice points along an edge.
        spacing_mm: f64,
    },
}

/// The albedo the phantom renders with: procedural, or baked on the truth mesh.
pub enum PhantomAlbedo {
    /// [`MucosaAlbedo::eval`] at the hit point.
    Procedural(MucosaAlbedo),
    /// The lattice lookup of [`BakedAlbedo`].
    Baked(BakedAlbedo),
}

impl PhantomAlbedo {
    /// The albedo `sampling` asks for, of `albedo` on the mesh of `scene`.
    pub fn new(albedo: MucosaAlbedo, sampling: AlbedoSampling, scene: &Scene) -> Self {
        match sampling {
            AlbedoSampling::Procedural => PhantomAlbedo::Procedural(albedo),
            AlbedoSampling::Baked { spacing_mm } => {
                PhantomAlbedo::Baked(BakedAlbedo::bake(&albedo, scene, spacing_mm))
            }
        }
    }

    /// Linear RGB albedo at a hit: triangle `tri`, barycentric weights `bary` of its second and
    /// third vertices, world point `point` (mm).
    #[inline]
    pub fn at(&self, tri: u32, bary: [f32; 2], point: [f32; 3]) -> [f32; 3] {
        match self {
            PhantomAlbedo::Procedural(a) => a.eval(Point3::new(
                point[0] as f64,
                point[1] as f64,
                point[2] as f64,
            )),
            PhantomAlbedo::Baked(b) => b.at(tri, bary),
        }
    }

    /// Linear RGB albedo at vertex `v` of the mesh, which is at `p` (world mm).
    pub fn at_vertex(&self, v: usize, p: Point3<f64>) -> [f32; 3] {
        match self {
            PhantomAlbedo::Procedural(a) => a.eval(p),
            PhantomAlbedo::Baked(b) => b.vertex_values[v],
        }
    }
}

/// The procedural albedo sampled on a barycentric lattice of every triangle.
pub struct BakedAlbedo {
    /// Lattice steps along each edge (the same for every triangle).
    n: usize,
    /// Samples per triangle, `(n + 1)(n + 2) / 2`, row `i` (weight `i/n` of the second vertex)
    /// then `j` (weight `j/n` of the third).
    per_triangle: usize,
    /// Linear RGB samples, triangle after triangle.
    samples: Vec<[f32; 3]>,
    /// The albedo at each vertex (the lattice's corners).
    vertex_values: Vec<[f32; 3]>,
}

impl BakedAlbedo {
    /// Bake `albedo` on the mesh of `scene` with lattice points at most `spacing_mm` apart.
    pub fn bake(albedo: &MucosaAlbedo, scene: &Scene, spacing_mm: f64) -> Self {
        let (pos, tris) = (&scene.positions, &scene.triangles);
        let longest = tris
            .iter()
            .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
            .map(|(a, b)| distance(pos[a as usize], pos[b as usize]))
            .fold(0.0f64, f64::max);
        let n = ((longest / spacing_mm.max(1e-6)).ceil() as usize).max(1);
        let per_triangle = (n + 1) * (n + 2) / 2;
        let eval = |p: [f64; 3]| albedo.eval(Point3::new(p[0], p[1], p[2]));
        let samples: Vec<[f32; 3]> = tris
            .par_iter()
            .with_min_len(64)
            .flat_map_iter(|t| {
                let v = t.map(|k| pos[k as usize].map(f64::from));
                (0..=n).flat_map(move |i| {
                    (0..=n - i).map(move |j| {
                        let w = [(n - i - j) as f64, i as f64, j as f64].map(|w| w / n as f64);
                        eval(weighted_point(&v, &w))
                    })
                })
            })
            .collect();
        let vertex_values = pos.par_iter().map(|p| eval(p.map(f64::from))).collect();
        BakedAlbedo {
            n,
            per_triangle,
            samples,
            vertex_values,
        }
    }

    /// Lattice steps along each edge.
    pub fn steps(&self) -> usize {
        self.n
    }

    /// The albedo at barycentric weights `bary` (second, third vertex) of triangle `tri`:
    /// linear interpolation in the lattice cell around it.
    #[inline]
    pub fn at(&self, tri: u32, bary: [f32; 2]) -> [f32; 3] {
        let n = self.n;
        let nf = n as f32;
        let mut x = bary[0].max(0.0) * nf;
        let mut y = bary[1].max(0.0) * nf;
        if x + y > nf {
            let s = nf / (x + y);
            x *= s;
            y *= s;
        }
        let i = (x.floor() as usize).min(n - 1);
        let j = (y.floor() as usize).min(n - 1 - i);
        let (fx, fy) = (x - i as f32, y - j as f32);
        let base = tri as usize * self.per_triangle;
        let at = |i: usize, j: usize| self.samples[base + row_start(i, n) + j];
        // The cell's upper triangle exists only off the lattice's diagonal edge.
        let (corners, weights) = if fx + fy > 1.0 && i + j + 2 <= n {
            (
                [at(i + 1, j + 1), at(i, j + 1), at(i + 1, j)],
                [fx + fy - 1.0, 1.0 - fx, 1.0 - fy],
            )
        } else {
            (
                [at(i, j), at(i + 1, j), at(i, j + 1)],
                [1.0 - fx - fy, fx, fy],
            )
        };
        std::array::from_fn(|c| {
            corners
                .iter()
                .zip(weights)
                .map(|(s, w)| s[c] * w)
                .sum::<f32>()
                .clamp(0.0, 1.0)
        })
    }
}

/// Index of lattice row `i` (weight `i/n` of the second vertex) in a triangle's samples.
#[inline]
fn row_start(i: usize, n: usize) -> usize {
    i * (n + 1) - i * i.saturating_sub(1) / 2
}

/// `sum_k w_k v_k`. Every weight is `k / n` with an integer k, and on an edge one term is
/// exactly zero, so both triangles that share the edge compute the same point (floating-point
/// addition of two terms is commutative).
fn weighted_point(v: &[[f64; 3]; 3], w: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| v[0][c] * w[0] + v[1][c] * w[1] + v[2][c] * w[2])
}

fn distance(a: [f32; 3], b: [f32; 3]) -> f64 {
    (0..3)
        .map(|c| (a[c] as f64 - b[c] as f64).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::rng::Pcg32;

    /// A 2 x 2 mm square in z = 1 split along its diagonal, the second triangle listing the
    /// shared vertices in the other order.
    fn square() -> Scene {
        let p = |x: f32, y: f32| Point3::new(x, y, 1.0);
        let mesh = TriMesh {
            positions: vec![p(0.0, 0.0), p(2.0, 0.0), p(2.0, 2.0), p(0.0, 2.0)],
            triangles: vec![[0, 1, 2], [2, 3, 0]],
        };
        Scene::new(&mesh).unwrap()
    }

    fn procedural(a: &MucosaAlbedo, p: [f64; 3]) -> [f32; 3] {
        a.eval(Point3::new(p[0], p[1], p[2]))
    }

    #[test]
    fn lattice_points_hold_the_procedural_albedo_and_edges_are_shared() {
        let albedo = MucosaAlbedo::new(7);
        let scene = square();
        let baked = BakedAlbedo::bake(&albedo, &scene, 0.1);
        // Longest edge 2 sqrt 2 mm: 29 steps of at most 0.1 mm.
        assert_eq!(baked.steps(), 29);
        let n = baked.steps() as f32;
        // Lattice point (i, j) of triangle 0 = [0, 1, 2]: weight i/n of vertex 1, j/n of 2.
        for (i, j) in [(0, 0), (3, 5), (10, 19), (29, 0), (0, 29)] {
            let got = baked.at(0, [i as f32 / n, j as f32 / n]);
            let w = [(29 - i - j) as f64, i as f64, j as f64].map(|w| w / 29.0);
            let pt = [2.0 * w[1] + 2.0 * w[2], 2.0 * w[2], 1.0];
            let want = procedural(&albedo, pt);
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() < 2e-4,
                    "({i},{j}) {got:?} {want:?}"
                );
            }
        }
        // The diagonal from vertex 0 to vertex 2 belongs to both triangles: triangle 0 sees a
        // point there with weight t of vertex 2, triangle 1 = [2, 3, 0] with weight t of its
        // first vertex (so 1 - t of its third). Both must give the same albedo.
        for k in 0..=40 {
            let t = k as f32 / 40.0;
            let a = baked.at(0, [0.0, t]);
            let b = baked.at(1, [0.0, 1.0 - t]);
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-5, "t {t}: {a:?} vs {b:?}");
            }
        }
        assert_eq!(baked.vertex_values[2], procedural(&albedo, [2.0, 2.0, 1.0]));
    }

    #[test]
    fn between_lattice_points_the_bake_follows_the_procedural_albedo() {
        let albedo = MucosaAlbedo::new(3);
        let scene = square();
        let baked = BakedAlbedo::bake(&albedo, &scene, 0.075);
        let mut rng = Pcg32::new(5, 1);
        let (mut sum, mut worst, n) = (0.0f64, 0.0f64, 4000);
        for _ in 0..n {
            let (u, v) = (rng.uniform(), rng.uniform());
            let (b1, b2) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            let got = baked.at(0, [b1 as f32, b2 as f32]);
            let want = procedural(&albedo, [2.0 * (b1 + b2), 2.0 * b2, 1.0]);
            let d = (0..3)
                .map(|c| (got[c] - want[c]).abs() as f64)
                .fold(0.0, f64::max);
            sum += d;
            worst = worst.max(d);
        }
        // Linear interpolation 0.075 mm apart of vessels 0.3-0.5 mm wide with soft edges.
        let mean = sum / n as f64;
        assert!(mean < 0.004, "mean abs difference {mean}");
        assert!(worst < 0.08, "largest difference {worst}");
    }
}
