//! Synthetic meshes and a seeded RNG shared by the ray-casting tests, benchmark and examples
//! (included with `#[path]`, so not every item is used by every includer).
#![allow(dead_code)]

use bronchosim::math::Point3;
use bronchosim::mesh::TriMesh;
use std::collections::HashMap;
use std::f32::consts::PI;
use std::io::Write;

pub use bronchosim::rng::SplitMix64 as Rng;

/// Icosphere of radius `r` (mm) centred at the origin, `levels` subdivisions, shared vertices
/// (closed, manifold), outward winding.
pub fn icosphere(r: f32, levels: u32) -> TriMesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut p: Vec<[f32; 3]> = vec![
        [-1., t, 0.],
        [1., t, 0.],
        [-1., -t, 0.],
        [1., -t, 0.],
        [0., -1., t],
        [0., 1., t],
        [0., -1., -t],
        [0., 1., -t],
        [t, 0., -1.],
        [t, 0., 1.],
        [-t, 0., -1.],
        [-t, 0., 1.],
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let norm = |v: [f32; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / l, v[1] / l, v[2] / l]
    };
    for v in &mut p {
        *v = norm(*v);
    }
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for tri in &f {
            let mut m = [0u32; 3];
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[e] = *mid.entry(key).or_insert_with(|| {
                    let (pa, pb) = (p[a as usize], p[b as usize]);
                    p.push(norm([pa[0] + pb[0], pa[1] + pb[1], pa[2] + pb[2]]));
                    (p.len() - 1) as u32
                });
            }
            nf.push([tri[0], m[0], m[2]]);
            nf.push([tri[1], m[1], m[0]]);
            nf.push([tri[2], m[2], m[1]]);
            nf.push([m[0], m[1], m[2]]);
        }
        f = nf;
    }
    TriMesh {
        positions: p
            .iter()
            .map(|v| Point3::new(v[0] * r, v[1] * r, v[2] * r))
            .collect(),
        triangles: f,
    }
}

/// Append to `m` an open tube along the straight centreline `p0 → p1` with radius
/// `radius(s, theta)` (s in [0, 1] along the axis), `rings` x `segs` quads, normals inward.
pub fn add_tube(
    m: &mut TriMesh,
    p0: [f32; 3],
    p1: [f32; 3],
    rings: usize,
    segs: usize,
    radius: &dyn Fn(f32, f32) -> f32,
) {
    let axis = sub(p1, p0);
    let len = dot(axis, axis).sqrt();
    let w = scale(axis, 1.0 / len);
    // Any unit vector perpendicular to w, then e2 = w x e1 so (e1, e2, w) is right handed.
    let helper = if w[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let e1 = normalize(cross(helper, w));
    let e2 = cross(w, e1);
    let base = m.positions.len() as u32;
    for i in 0..=rings {
        let s = i as f32 / rings as f32;
        let c = add(p0, scale(axis, s));
        for j in 0..segs {
            let th = 2.0 * PI * j as f32 / segs as f32;
            let r = radius(s, th);
            let p = add(c, add(scale(e1, r * th.cos()), scale(e2, r * th.sin())));
            m.positions.push(Point3::new(p[0], p[1], p[2]));
        }
    }
    let segs32 = segs as u32;
    for i in 0..rings as u32 {
        for j in 0..segs32 {
            let a = base + i * segs32 + j;
            let b = base + i * segs32 + (j + 1) % segs32;
            let (c, d) = (a + segs32, b + segs32);
            // (a, c, b): axis x tangent points inward.
            m.triangles.push([a, c, b]);
            m.triangles.push([b, c, d]);
        }
    }
}

/// Close the ring of `segs` vertices starting at `first` with a fan around a new centre vertex.
pub fn add_cap(m: &mut TriMesh, first: u32, segs: u32, centre: [f32; 3]) {
    m.positions
        .push(Point3::new(centre[0], centre[1], centre[2]));
    let c = (m.positions.len() - 1) as u32;
    for j in 0..segs {
        m.triangles.push([c, first + j, first + (j + 1) % segs]);
    }
}

/// A branch: centreline start, end (mm) and mean radius (mm).
pub type Branch = ([f32; 3], [f32; 3], f32);

/// A trachea-like tube splitting into two and then four bronchi, with smooth radius noise and
/// closed far ends; edge length about `h` mm. Returns the mesh and the branch centrelines
/// (start, end, mean radius) so callers can place cameras and ray origins inside.
pub fn branching_airway(h: f32) -> (TriMesh, Vec<Branch>) {
    let mut branches = vec![([0.0, 0.0, 0.0], [0.0, 0.0, 100.0], 8.0f32)];
    let rot = |d: [f32; 3], ax: usize, ang: f32| -> [f32; 3] {
        let (c, s) = (ang.cos(), ang.sin());
        match ax {
            0 => [d[0], c * d[1] - s * d[2], s * d[1] + c * d[2]],
            _ => [c * d[0] + s * d[2], d[1], -s * d[0] + c * d[2]],
        }
    };
    let mut gen = vec![(branches[0].1, [0.0f32, 0.0, 1.0], 8.0f32)];
    for (g, (len, r)) in [(50.0f32, 6.0f32), (35.0, 4.0)].into_iter().enumerate() {
        let mut next = Vec::new();
        for (start, dir, pr) in gen {
            for sign in [-1.0f32, 1.0] {
                let d = rot(dir, if g == 0 { 1 } else { 0 }, sign * 0.6);
                // Start a parent radius back inside the parent so the walls overlap.
                let p0 = sub(start, scale(d, 0.8 * pr));
                let p1 = add(start, scale(d, len));
                branches.push((p0, p1, r));
                next.push((p1, d, r));
            }
        }
        gen = next;
    }
    let mut m = TriMesh::default();
    for (k, &(p0, p1, r)) in branches.iter().enumerate() {
        let len = dot(sub(p1, p0), sub(p1, p0)).sqrt();
        let segs = ((2.0 * PI * r / h).ceil() as usize).max(8);
        let rings = ((len / h).ceil() as usize).max(1);
        let ph = k as f32 * 1.7;
        let radius = move |s: f32, th: f32| {
            r * (1.0
                + 0.06 * (3.0 * th + ph + 9.0 * s).sin()
                + 0.04 * (7.0 * th - 2.0 * ph + 23.0 * s).sin()
                + 0.03 * (41.0 * s + ph).sin())
        };
        let first = m.positions.len() as u32;
        add_tube(&mut m, p0, p1, rings, segs, &radius);
        if k == 0 {
            add_cap(&mut m, first, segs as u32, p0);
        }
        if k >= 3 {
            let last = first + (rings * segs) as u32;
            add_cap(&mut m, last, segs as u32, p1);
        }
    }
    (m, branches)
}

/// Rays for the throughput benchmark, origin and unit direction each.
pub struct BenchRays {
    pub origins: Vec<[f32; 3]>,
    pub dirs: Vec<[f32; 3]>,
}

/// The benchmark scene: the branching airway at edge length 0.3 mm (about 300k triangles),
/// a 512x512 pinhole camera (fx = fy = 256 px, 90 degree field of view) in the trachea looking
/// down it, and 262144 incoherent rays from random points inside the branches.
pub fn bench_scene() -> (TriMesh, BenchRays, BenchRays) {
    let (mesh, branches) = branching_airway(0.3);
    let (w, f) = (512usize, 256.0f32);
    let org = [0.5, -0.8, 30.0];
    // Camera looks along +z tilted slightly towards +x; x axis right, y down.
    let fwd = normalize([0.1, 0.05, 1.0]);
    let right = normalize(cross([0.0, 1.0, 0.0], fwd));
    let down = cross(fwd, right);
    let mut cam = BenchRays {
        origins: Vec::new(),
        dirs: Vec::new(),
    };
    for v in 0..w {
        for u in 0..w {
            let x = (u as f32 - 255.5) / f;
            let y = (v as f32 - 255.5) / f;
            cam.origins.push(org);
            cam.dirs
                .push(normalize(add(add(scale(right, x), scale(down, y)), fwd)));
        }
    }
    let mut rng = Rng::new(7);
    let mut rnd = BenchRays {
        origins: Vec::new(),
        dirs: Vec::new(),
    };
    for _ in 0..262_144 {
        let (p0, p1, r) = branches[(rng.next_u64() % branches.len() as u64) as usize];
        let c = add(p0, scale(sub(p1, p0), rng.range_f32(0.2, 0.9)));
        let off = scale(rng.unit_vector(), 0.4 * r);
        rnd.origins.push(add(c, off));
        rnd.dirs.push(rng.unit_vector());
    }
    (mesh, cam, rnd)
}

/// Write `m` as binary little-endian PLY (float xyz, uchar/int vertex_indices).
pub fn write_ply(m: &TriMesh, path: &std::path::Path) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.positions.len(),
        m.triangles.len()
    )?;
    for p in &m.positions {
        for c in [p.x, p.y, p.z] {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    for t in &m.triangles {
        w.write_all(&[3u8])?;
        for &i in t {
            w.write_all(&(i as i32).to_le_bytes())?;
        }
    }
    w.flush()
}

pub fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn normalize(a: [f32; 3]) -> [f32; 3] {
    scale(a, 1.0 / dot(a, a).sqrt())
}
