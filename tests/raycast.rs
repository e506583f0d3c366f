//! Ray casting: watertightness, agreement with a brute-force caster and with Embree, and a
//! G-buffer known answer inside an analytic cylinder.

#[path = "common/meshes.rs"]
mod meshes;

use bronchosim::camera::Camera;
use bronchosim::math::{Affine, Point3, Vector3};
use bronchosim::mesh::TriMesh;
use bronchosim::raycast::triangle::{intersect, ShearedRay};
use bronchosim::raycast::{cast_depth_with, cast_frame, mask_out_depth, RayTable, Scene};
use meshes::{dot, icosphere, sub, Rng};
use std::collections::HashMap;

fn tri_vertices(m: &TriMesh, t: usize) -> [[f32; 3]; 3] {
    m.triangles[t].map(|i| {
        let p = m.positions[i as usize];
        [p.x, p.y, p.z]
    })
}

/// All hits of a ray (t, tri), by testing every triangle with the scalar watertight test.
fn brute_all(m: &TriMesh, o: [f32; 3], d: [f32; 3], tmax: f32) -> Vec<(f32, u32)> {
    let r = ShearedRay::new(o, d);
    (0..m.triangles.len())
        .filter_map(|t| {
            let [a, b, c] = tri_vertices(m, t);
            intersect(&r, a, b, c, tmax).map(|h| (h.t, t as u32))
        })
        .collect()
}

fn brute_closest(m: &TriMesh, o: [f32; 3], d: [f32; 3], tmax: f32) -> Option<(f32, u32)> {
    brute_all(m, o, d, tmax)
        .into_iter()
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

fn p3(p: Point3<f32>) -> [f32; 3] {
    [p.x, p.y, p.z]
}

/// Rays from inside a closed icosphere through every vertex and every shared edge's midpoint
/// (where a cracked intersector loses rays between triangles): each ray meets the surface
/// exactly once (all brute-force hits at one distance), the BVH reports it with the expected
/// t and an adjacent triangle, and any-hit agrees just before and after the surface.
#[test]
fn no_cracks_at_shared_edges_and_vertices() {
    let m = icosphere(10.0, 3);
    let scene = Scene::new(&m).unwrap();
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    let mut around: HashMap<u32, Vec<u32>> = HashMap::new();
    for (t, tri) in m.triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push(t as u32);
            around.entry(a).or_default().push(t as u32);
        }
    }
    assert!(
        edges.values().all(|f| f.len() == 2),
        "icosphere must be closed"
    );
    let mut targets: Vec<([f32; 3], Vec<u32>)> = Vec::new();
    for (&(a, b), f) in &edges {
        let (pa, pb) = (p3(m.positions[a as usize]), p3(m.positions[b as usize]));
        targets.push(([0, 1, 2].map(|i| 0.5 * (pa[i] + pb[i])), f.clone()));
    }
    for (&v, f) in &around {
        targets.push((p3(m.positions[v as usize]), f.clone()));
    }
    assert_eq!(targets.len(), 1920 + 642);
    let mut checked = 0;
    for origin in [[0.0f32, 0.0, 0.0], [1.3, -2.1, 0.7], [-4.0, 3.5, -2.5]] {
        for (p, adjacent) in &targets {
            let d = sub(*p, origin);
            let expect = dot(d, d).sqrt();
            let dir = d.map(|c| c / expect);
            let all = brute_all(&m, origin, dir, f32::INFINITY);
            assert!(
                !all.is_empty(),
                "brute force: ray from {origin:?} to {p:?} falls through a crack"
            );
            for &(t, _) in &all {
                assert!(
                    (t - expect).abs() <= 1e-5 * expect,
                    "second crossing at t = {t}, expected {expect}"
                );
            }
            let h = scene
                .closest_hit(origin, dir, f32::INFINITY)
                .expect("BVH: ray through a crack");
            assert!(
                (h.t - expect).abs() <= 1e-5 * expect,
                "t = {}, expected {expect}",
                h.t
            );
            assert!(
                adjacent.contains(&h.tri),
                "hit triangle {} not adjacent to {p:?}",
                h.tri
            );
            assert!(scene.any_hit(origin, dir, expect * 1.001));
            assert!(!scene.any_hit(origin, dir, expect * 0.999));
            checked += 1;
        }
    }
    assert_eq!(checked, 3 * 2562);
}

/// 10k seeded random rays from inside a closed, noisy sphere: every one hits (no cracks).
#[test]
fn closed_mesh_random_rays_never_escape() {
    let mut m = icosphere(10.0, 4);
    let mut rng = Rng::new(11);
    for p in &mut m.positions {
        let s = 1.0 + 0.05 * rng.range_f32(-1.0, 1.0);
        *p = Point3::new(p.x * s, p.y * s, p.z * s);
    }
    let scene = Scene::new(&m).unwrap();
    for _ in 0..10_000 {
        let o = meshes::scale(rng.unit_vector(), rng.range_f32(0.0, 5.0));
        let d = rng.unit_vector();
        let h = scene.closest_hit(o, d, f32::INFINITY);
        assert!(
            h.is_some_and(|h| h.t > 3.0 && h.t < 20.0),
            "ray {o:?} {d:?} escaped: {h:?}"
        );
    }
}

/// A random-ish mesh (noisy sphere plus a soup of 2000 random triangles) and 2 x 10k seeded
/// random rays: each BVH's closest hit equals the brute-force one (same triangle, or a tie at the same t;
/// t within 1e-5 relative), and any-hit with a random tmax agrees.
#[test]
fn bvh_agrees_with_brute_force() {
    let mut m = icosphere(12.0, 3);
    let mut rng = Rng::new(42);
    for p in &mut m.positions {
        let s = 1.0 + 0.08 * rng.range_f32(-1.0, 1.0);
        *p = Point3::new(p.x * s, p.y * s, p.z * s);
    }
    for _ in 0..2000 {
        let c = [
            rng.range_f32(-10.0, 10.0),
            rng.range_f32(-10.0, 10.0),
            rng.range_f32(-10.0, 10.0),
        ];
        let base = m.positions.len() as u32;
        for _ in 0..3 {
            m.positions.push(Point3::new(
                c[0] + rng.range_f32(-1.5, 1.5),
                c[1] + rng.range_f32(-1.5, 1.5),
                c[2] + rng.range_f32(-1.5, 1.5),
            ));
        }
        m.triangles.push([base, base + 1, base + 2]);
    }
    let scenes = [Scene::new(&m).unwrap(), Scene::new_four_wide(&m).unwrap()];
    let (mut hits, mut ties) = (0, 0);
    for k in 0..20_000 {
        // Even rays: the default (eight-wide on AVX2) BVH; odd rays: the portable four-wide one.
        let scene = &scenes[k % 2];
        let o = [
            rng.range_f32(-14.0, 14.0),
            rng.range_f32(-14.0, 14.0),
            rng.range_f32(-14.0, 14.0),
        ];
        let d = rng.unit_vector();
        let bvh = scene.closest_hit(o, d, f32::INFINITY);
        let brute = brute_closest(&m, o, d, f32::INFINITY);
        match (bvh, brute) {
            (None, None) => {}
            (Some(h), Some((t, tri))) => {
                hits += 1;
                assert!((h.t - t).abs() <= 1e-5 * t, "t {} vs brute {t}", h.t);
                if h.tri != tri {
                    ties += 1;
                    let alt = brute_all(&m, o, d, f32::INFINITY);
                    assert!(
                        alt.iter().any(|&(ta, ia)| ia == h.tri && ta == h.t),
                        "BVH hit is not a hit"
                    );
                }
            }
            (a, b) => panic!("ray {o:?} {d:?}: BVH {a:?}, brute force {b:?}"),
        }
        let tmax = rng.range_f32(0.0, 30.0);
        assert_eq!(
            scene.any_hit(o, d, tmax),
            brute_closest(&m, o, d, tmax).is_some()
        );
    }
    assert!(hits > 10_000, "only {hits} hits: the test would be weak");
    assert!(ties < 10, "{ties} ties");
}

#[derive(serde::Deserialize)]
struct Reference {
    vertices: Vec<[f32; 3]>,
    faces: Vec<[u32; 3]>,
    origins: Vec<[f32; 3]>,
    dirs: Vec<[f32; 3]>,
    tri: Vec<i64>,
    t: Vec<f32>,
}

/// Closest hits against Embree (robust mode) on a committed mesh and 2000 rays
/// (scripts/reference/raycast_embree.py): same hit/miss and triangle for every ray, t within
/// 1e-5 (t + 10 mm).
#[test]
fn agrees_with_embree_reference() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/raycast_reference.json"
    ))
    .unwrap();
    let r: Reference = serde_json::from_str(&text).unwrap();
    let m = TriMesh {
        positions: r
            .vertices
            .iter()
            .map(|p| Point3::new(p[0], p[1], p[2]))
            .collect(),
        triangles: r.faces.clone(),
    };
    let scene = Scene::new(&m).unwrap();
    let hits = scene.closest_hits(&r.origins, &r.dirs, f32::INFINITY);
    let mut n_hit = 0;
    for (i, h) in hits.iter().enumerate() {
        match h {
            None => assert_eq!(
                r.tri[i], -1,
                "ray {i}: Embree hit triangle {}, we missed",
                r.tri[i]
            ),
            Some(h) => {
                n_hit += 1;
                assert_eq!(h.tri as i64, r.tri[i], "ray {i}: triangle");
                // Embree's t error scales with the coordinates (~10 mm), not with t.
                let tol = 1e-5 * (r.t[i] + 10.0);
                assert!(
                    (h.t - r.t[i]).abs() <= tol,
                    "ray {i}: t {} vs Embree {}",
                    h.t,
                    r.t[i]
                );
            }
        }
    }
    assert_eq!(n_hit, r.tri.iter().filter(|&&t| t >= 0).count());
}

/// A distorted camera off the axis of an analytic cylinder (radius 5 mm, 512 facets) looking
/// along it: per pixel, z equals the analytic ray–cylinder distance and gamma the analytic
/// cosine, within the facets' sag; normals face the camera; open-end pixels miss. The
/// depth-only cast gives the same z to the bit, also masked.
#[test]
fn gbuffer_matches_analytic_cylinder() {
    let (radius, segs, half) = (5.0f32, 512usize, 40.0f32);
    let mut m = TriMesh::default();
    meshes::add_tube(
        &mut m,
        [-half, 0.0, 0.0],
        [half, 0.0, 0.0],
        160,
        segs,
        &|_, _| radius,
    );
    let scene = Scene::new(&m).unwrap();
    let cam = Camera {
        width: 160,
        height: 120,
        fx: 90.0,
        fy: 92.0,
        cx: 80.3,
        cy: 59.1,
        k1: -0.25,
        k2: 0.06,
        p1: 0.001,
        p2: -0.002,
        k3: 0.0,
    };
    // Camera +z looks along world +x, camera +x is world +y, camera +y is world +z.
    let o = [-20.0f64, 0.8, -1.1];
    #[rustfmt::skip]
    let pose = Affine::new(
        0.0, 0.0, 1.0, o[0],
        1.0, 0.0, 0.0, o[1],
        0.0, 1.0, 0.0, o[2],
        0.0, 0.0, 0.0, 1.0,
    );
    let g = cast_frame(&scene, &cam, &pose);
    assert_eq!(g.z.len(), 160 * 120);
    let depth = cast_depth_with(&scene, &RayTable::new(&cam), &pose);
    assert!(
        depth.len() == g.z.len()
            && depth
                .iter()
                .zip(&g.z)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
        "the depth-only cast differs from the G-buffer's z"
    );
    // Masked alike: a disc of the image left out.
    let image: Vec<bool> = (0..160 * 120)
        .map(|i: i32| (i % 160 - 60).pow(2) + (i / 160 - 50).pow(2) > 400)
        .collect();
    let (mut masked, mut masked_depth) = (g.clone(), depth.clone());
    masked.mask_out(&image);
    mask_out_depth(&mut masked_depth, &image);
    assert!(
        masked_depth
            .iter()
            .zip(&masked.z)
            .all(|(a, b)| a.to_bits() == b.to_bits())
            && masked.hit_count() < g.hit_count(),
        "the masked depth differs from the masked G-buffer's z"
    );
    let sag = radius as f64 * (1.0 - (std::f64::consts::PI / segs as f64).cos());
    let (mut n_hit, mut n_miss, mut worst_z, mut worst_gamma) = (0, 0, 0.0f64, 0.0f64);
    for v in 0..cam.height {
        for u in 0..cam.width {
            let i = (v * cam.width + u) as usize;
            let c = cam.pixel_ray(u as f64, v as f64);
            let d = Vector3::new(c.z, c.x, c.y); // camera → world rotation above
            let (a, b) = (d.y * d.y + d.z * d.z, 2.0 * (o[1] * d.y + o[2] * d.z));
            let cc = o[1] * o[1] + o[2] * o[2] - (radius as f64).powi(2);
            let t = (-b + (b * b - 4.0 * a * cc).sqrt()) / (2.0 * a);
            let x_hit = o[0] + t * d.x;
            if x_hit > half as f64 + 1.0 {
                assert!(!g.hit(i), "pixel ({u}, {v}) should see out of the open end");
                n_miss += 1;
                continue;
            }
            if x_hit > half as f64 - 1.0 {
                continue; // the rim: hit or miss depends on the facet, not tested
            }
            assert!(g.hit(i), "pixel ({u}, {v}) missed the cylinder");
            n_hit += 1;
            let p = [o[0] + t * d.x, o[1] + t * d.y, o[2] + t * d.z];
            let n_in = Vector3::new(0.0, -p[1], -p[2]) / radius as f64;
            let gamma = -d.dot(&n_in);
            // A facet sits up to `sag` inside the circle: the depth error grows as 1/gamma.
            let dz = (g.z[i] as f64 - t).abs();
            assert!(
                dz <= 1.5 * sag / gamma + 2e-5 * t,
                "pixel ({u}, {v}): z {} vs {t}",
                g.z[i]
            );
            let dg = (g.gamma[i] as f64 - gamma).abs();
            assert!(
                dg <= 2e-3,
                "pixel ({u}, {v}): gamma {} vs {gamma}",
                g.gamma[i]
            );
            worst_z = worst_z.max(dz / t);
            worst_gamma = worst_gamma.max(dg);
            let q = g.point[i];
            let to_cam = [o[0] - q[0] as f64, o[1] - q[1] as f64, o[2] - q[2] as f64];
            let nrm = g.normal[i];
            let facing =
                to_cam[0] * nrm[0] as f64 + to_cam[1] * nrm[1] as f64 + to_cam[2] * nrm[2] as f64;
            assert!(
                facing > 0.0,
                "pixel ({u}, {v}): normal faces away from the camera"
            );
            let r_hit = ((q[1] as f64).powi(2) + (q[2] as f64).powi(2)).sqrt();
            assert!(r_hit <= radius as f64 + 1e-4 && r_hit >= radius as f64 - sag - 1e-4);
        }
    }
    assert!(
        n_hit > 15_000 && n_miss > 50,
        "{n_hit} hits, {n_miss} misses"
    );
    eprintln!("cylinder: {n_hit} hits, {n_miss} misses, worst z rel {worst_z:.2e}, worst gamma {worst_gamma:.2e}");
}

/// Packet tracing (`Scene::closest_hits_common_origin`) against single rays on the branching
/// airway (about 80k triangles), with both BVH widths. Origins: inside the trachea looking down
/// (coherent camera rows, near and far hits), outside the airway (packets where some rays hit
/// the wall and their neighbours miss), and random directions (packets whose directions change
/// sign on every axis); also a finite tmax (some rays of a packet stop before the wall) and a
/// ray count that is not a multiple of the packet size (16). Every ray: hit/miss identical, the same triangle
/// (or an exact tie in t), t within 1e-5 (t + 10). The camera part (61 x 47 rays: partial 4x4
/// tiles) also through `closest_hits_image_rows`, which must equal the plain packet call.
#[test]
fn packets_match_single_rays() {
    let (m, _) = meshes::branching_airway(0.6);
    let scenes = [Scene::new(&m).unwrap(), Scene::new_four_wide(&m).unwrap()];
    let mut rng = Rng::new(99);
    // (origin, forward, field of view scale, tmax)
    let views: [([f32; 3], [f32; 3], f32, f32); 5] = [
        ([0.5, -0.8, 30.0], [0.1, 0.05, 1.0], 1.0, f32::INFINITY),
        ([0.5, -0.8, 30.0], [0.1, 0.05, 1.0], 1.0, 60.0),
        ([-1.0, 2.0, 60.0], [0.9, 0.2, -0.3], 2.0, f32::INFINITY),
        ([40.0, 5.0, 100.0], [-1.0, 0.0, 0.3], 0.4, f32::INFINITY),
        ([-30.0, -30.0, 150.0], [0.3, 0.3, -1.0], 0.6, f32::INFINITY),
    ];
    let (w, h) = (61usize, 47usize);
    let (mut n_hit, mut n_miss, mut ties, mut mixed_packets) = (0, 0, 0, 0);
    for (vi, &(org, fwd, fov, tmax)) in views.iter().enumerate() {
        let fwd = meshes::normalize(fwd);
        let right = meshes::normalize(meshes::cross([0.0, 1.0, 0.0], fwd));
        let down = meshes::cross(fwd, right);
        let mut dirs: Vec<[f32; 3]> = Vec::new();
        for v in 0..h {
            for u in 0..w {
                let x = fov * (u as f32 - w as f32 / 2.0) / w as f32;
                let y = fov * (v as f32 - h as f32 / 2.0) / w as f32;
                let d = meshes::add(
                    meshes::add(meshes::scale(right, x), meshes::scale(down, y)),
                    fwd,
                );
                dirs.push(meshes::normalize(d));
            }
        }
        // Then incoherent packets: random directions, a few of them axis-aligned.
        for k in 0..16 * 20 + 5 {
            let mut d = rng.unit_vector();
            if k % 29 == 0 {
                d = [0.0, 0.0, if k % 2 == 0 { 1.0 } else { -1.0 }];
            }
            dirs.push(d);
        }
        for packet in dirs.chunks(16) {
            let neg = (0..3)
                .filter(|&a| packet.iter().any(|d| d[a] < 0.0))
                .count();
            let pos = (0..3)
                .filter(|&a| packet.iter().any(|d| d[a] > 0.0))
                .count();
            if neg == 3 && pos == 3 {
                mixed_packets += 1;
            }
        }
        for (si, scene) in scenes.iter().enumerate() {
            let mut got = vec![None; dirs.len()];
            scene.closest_hits_common_origin(org, &dirs, tmax, &mut got);
            let mut tiled = vec![None; w * h];
            scene.closest_hits_image_rows(org, &dirs[..w * h], w, tmax, &mut tiled);
            assert_eq!(tiled, got[..w * h], "view {vi}, scene {si}: tiled order");
            for (i, d) in dirs.iter().enumerate() {
                let one = scene.closest_hit(org, *d, tmax);
                let ctx = format!("view {vi}, scene {si}, ray {i} {d:?}");
                match (got[i], one) {
                    (None, None) => n_miss += 1,
                    (Some(p), Some(s)) => {
                        n_hit += 1;
                        assert!(
                            (p.t - s.t).abs() <= 1e-5 * (s.t + 10.0),
                            "{ctx}: t {} vs {}",
                            p.t,
                            s.t
                        );
                        if p.tri != s.tri {
                            assert_eq!(p.t, s.t, "{ctx}: triangle {} vs {}", p.tri, s.tri);
                            ties += 1;
                        } else {
                            assert_eq!((p.u, p.v), (s.u, s.v), "{ctx}: barycentrics");
                        }
                    }
                    (p, s) => panic!("{ctx}: packet {p:?}, single {s:?}"),
                }
            }
        }
    }
    eprintln!("packets: {n_hit} hits, {n_miss} misses, {ties} ties, {mixed_packets} all-axes-mixed packets");
    assert!(
        n_hit > 20_000 && n_miss > 2_000,
        "{n_hit} hits, {n_miss} misses"
    );
    assert!(mixed_packets > 100, "{mixed_packets} mixed packets");
    assert!(ties <= 10, "{ties} ties");
}
