//! Texture atlas: quality on a synthetic airway, no bleeding across charts, texel geometry, and
//! hole filling.

mod common {
    pub mod airway_mesh;
}

use std::sync::OnceLock;

use bronchosim::math::{Point3, Vector3};
use bronchosim::mesh::TriMesh;
use bronchosim::texture::atlas::{
    build_atlas, fill_uncovered, rasterize_texels, Atlas, AtlasOptions, TexelGeometry,
};
use common::airway_mesh::airway_mesh;

/// The airway at 0.8 mm grid spacing (~50k triangles), its atlas and texel geometry, built once.
fn airway() -> &'static (TriMesh, Atlas, TexelGeometry) {
    static CELL: OnceLock<(TriMesh, Atlas, TexelGeometry)> = OnceLock::new();
    CELL.get_or_init(|| {
        let mesh = airway_mesh(0.8);
        let atlas = build_atlas(&mesh, &AtlasOptions::default()).expect("atlas");
        let geo = rasterize_texels(&atlas, &mesh).expect("texels");
        eprintln!(
            "airway: {} triangles, {} charts, {}x{} texels, {:?}",
            mesh.triangles.len(),
            atlas.chart_count,
            atlas.width,
            atlas.height,
            atlas.stats
        );
        (mesh, atlas, geo)
    })
}

/// UV of atlas vertex `v` in texel units.
fn uv_texels(a: &Atlas, v: u32) -> [f64; 2] {
    let p = a.uv[v as usize];
    [p[0] as f64 * a.width as f64, p[1] as f64 * a.height as f64]
}

fn signed_area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
}

/// A tiny deterministic generator (64-bit LCG), so failures reproduce.
#[test]
fn airway_atlas_meets_quality_targets() {
    let (mesh, a, _) = airway();
    assert!(
        mesh.triangles.len() > 30_000,
        "{} triangles",
        mesh.triangles.len()
    );
    assert!(
        a.stats.utilisation >= 0.60,
        "utilisation {}",
        a.stats.utilisation
    );
    assert!(
        a.stats.mean_l2_stretch < 1.10,
        "mean L2 stretch {}",
        a.stats.mean_l2_stretch
    );
    assert!(
        a.stats.mean_l2_stretch >= 1.0 - 1e-9,
        "L2 stretch below 1 is impossible"
    );
    assert_eq!(a.stats.flipped_triangles, 0);
    assert!(a.width <= 16384 && a.height <= 16384);
    // Charts are bounded by the normal cone: many of them on a tube.
    assert!(a.chart_count >= 8, "{} charts", a.chart_count);

    // Independent recount: every triangle has positive UV area, lies in [0,1]², and its atlas
    // corners are the input's corners.
    let mut uv_area = 0.0;
    for (t, (&at, &mt)) in a.mesh.triangles.iter().zip(&mesh.triangles).enumerate() {
        let [p, q, r] = at.map(|v| uv_texels(a, v));
        let s = signed_area(p, q, r);
        assert!(s > 0.0, "triangle {t} has UV area {s}");
        uv_area += s;
        for k in 0..3 {
            assert_eq!(a.original_vertex[at[k] as usize], mt[k]);
            assert_eq!(
                a.mesh.positions[at[k] as usize],
                mesh.positions[mt[k] as usize]
            );
        }
        for x in [p, q, r] {
            assert!(x[0] >= 0.0 && x[1] >= 0.0);
            assert!(x[0] <= a.width as f64 && x[1] <= a.height as f64);
        }
    }
    // Uniform texel density: UV area (texels) times texel area equals the surface area.
    let surface = mesh.area();
    let rel = (uv_area * a.texel_mm * a.texel_mm - surface).abs() / surface;
    assert!(
        rel < 1e-3,
        "UV area {uv_area} texels vs surface {surface} mm²"
    );
}

#[test]
fn straight_tube_unrolls_isometrically() {
    // An open cylinder, radius 5 mm, length 40 mm: developable, so LSCM charts are isometries.
    let (nu, nv, r, len) = (96usize, 160usize, 5.0f32, 40.0f32);
    let mut positions = Vec::new();
    for j in 0..=nv {
        for i in 0..nu {
            let phi = i as f32 / nu as f32 * std::f32::consts::TAU;
            positions.push(Point3::new(
                r * phi.cos(),
                r * phi.sin(),
                j as f32 / nv as f32 * len,
            ));
        }
    }
    let mut triangles = Vec::new();
    for j in 0..nv as u32 {
        for i in 0..nu as u32 {
            let (a, b) = (j * nu as u32 + i, j * nu as u32 + (i + 1) % nu as u32);
            let (c, d) = (a + nu as u32, b + nu as u32);
            triangles.push([a, c, b]);
            triangles.push([b, c, d]);
        }
    }
    let mesh = TriMesh {
        positions,
        triangles,
    };
    let a = build_atlas(&mesh, &AtlasOptions::default()).unwrap();
    assert!(a.stats.mean_l2_stretch < 1.005, "{:?}", a.stats);
    assert!(a.stats.max_l2_stretch < 1.05, "{:?}", a.stats);
    // A 60° normal cone cannot hold more than 120° of the circumference: at least 3 charts.
    assert!(a.chart_count >= 3, "{} charts", a.chart_count);
    assert_eq!(a.stats.flipped_triangles, 0);
}

#[test]
fn bilinear_lookups_never_leave_their_chart() {
    let (_, a, geo) = airway();
    let map = geo.chart_map();
    let (w, h) = (a.width as i64, a.height as i64);
    let mut rng = bronchosim::rng::SplitMix64::new(7);
    let mut checked = 0usize;
    for (t, tri) in a.mesh.triangles.iter().enumerate() {
        let chart = a.chart_of_triangle[t];
        let [p, q, r] = tri.map(|v| uv_texels(a, v));
        let mut samples = vec![p, q, r];
        for _ in 0..6 {
            let (mut s, mut u) = (rng.uniform(), rng.uniform());
            if s + u > 1.0 {
                (s, u) = (1.0 - s, 1.0 - u);
            }
            samples.push([
                p[0] + s * (q[0] - p[0]) + u * (r[0] - p[0]),
                p[1] + s * (q[1] - p[1]) + u * (r[1] - p[1]),
            ]);
        }
        for x in samples {
            // Bilinear lookup: texel centres at i + 0.5; weights of the 2x2 neighbourhood.
            let (fx, fy) = (x[0] - 0.5, x[1] - 0.5);
            let (ix, iy) = (fx.floor() as i64, fy.floor() as i64);
            let (wx, wy) = (fx - ix as f64, fy - iy as f64);
            for (dx, dy, wt) in [
                (0, 0, (1.0 - wx) * (1.0 - wy)),
                (1, 0, wx * (1.0 - wy)),
                (0, 1, (1.0 - wx) * wy),
                (1, 1, wx * wy),
            ] {
                if wt <= 0.0 {
                    continue;
                }
                let (tx, ty) = (ix + dx, iy + dy);
                assert!(
                    tx >= 0 && ty >= 0 && tx < w && ty < h,
                    "lookup outside the atlas"
                );
                let got = map[(ty * w + tx) as usize];
                assert_eq!(
                    got, chart,
                    "triangle {t} (chart {chart}) reads texel ({tx},{ty}) of chart {got}"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 1_000_000 / 4, "{checked} lookups");
}

/// Closest point to `p` on triangle `abc` (Ericson, Real-Time Collision Detection 5.1.5).
fn closest_on_triangle(
    p: Vector3<f64>,
    a: Vector3<f64>,
    b: Vector3<f64>,
    c: Vector3<f64>,
) -> Vector3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[test]
fn texel_points_lie_on_their_triangles_and_map_back() {
    let (mesh, a, geo) = airway();
    assert!(!geo.is_empty());
    let w = a.width as usize;
    let mut inside = 0usize;
    let mut smooth = 0usize;
    for i in 0..geo.len() {
        let t = geo.triangle[i] as usize;
        let tex = geo.texel[i] as usize;
        let centre = [(tex % w) as f64 + 0.5, (tex / w) as f64 + 0.5];
        let corners = a.mesh.triangles[t].map(|v| uv_texels(a, v));
        let p3 = mesh.triangles[t].map(|v| mesh.positions[v as usize].coords.cast::<f64>());
        let l = geo.bary[i].map(|x| x as f64);
        // The barycentrics reproduce the texel centre in UV.
        let back = [
            l[0] * corners[0][0] + l[1] * corners[1][0] + l[2] * corners[2][0],
            l[0] * corners[0][1] + l[1] * corners[1][1] + l[2] * corners[2][1],
        ];
        assert!(
            (back[0] - centre[0]).abs() < 2e-3 && (back[1] - centre[1]).abs() < 2e-3,
            "texel {tex}: barycentrics give {back:?}, centre {centre:?}"
        );
        // The point is the barycentric combination, on the triangle's plane.
        let pt = Vector3::new(
            geo.point[i][0] as f64,
            geo.point[i][1] as f64,
            geo.point[i][2] as f64,
        );
        let expect = p3[0] * l[0] + p3[1] * l[1] + p3[2] * l[2];
        assert!(
            (pt - expect).norm() < 1e-4,
            "texel {tex}: point off by {}",
            (pt - expect).norm()
        );
        let n_face = (p3[1] - p3[0]).cross(&(p3[2] - p3[0])).normalize();
        assert!(
            (pt - p3[0]).dot(&n_face).abs() < 1e-4,
            "texel {tex} off the plane"
        );
        if l.iter().all(|&x| x >= 0.0) {
            let d = (closest_on_triangle(pt, p3[0], p3[1], p3[2]) - pt).norm();
            assert!(d < 1e-4, "texel {tex}: {d} mm from its triangle");
            inside += 1;
        } else {
            // Extrapolated texels are within bilinear reach of their triangle: the centre is at
            // most one texel off it along each axis, so at most sqrt(2) texels away in UV.
            let lift = |q: [f64; 2]| Vector3::new(q[0], q[1], 0.0);
            let c2 = lift(centre);
            let d = (closest_on_triangle(c2, lift(corners[0]), lift(corners[1]), lift(corners[2]))
                - c2)
                .norm();
            assert!(
                d <= std::f64::consts::SQRT_2 + 1e-3,
                "texel {tex}: {d} texels from its triangle"
            );
        }
        let n = Vector3::new(
            geo.normal[i][0] as f64,
            geo.normal[i][1] as f64,
            geo.normal[i][2] as f64,
        );
        assert!((n.norm() - 1.0).abs() < 1e-5);
        if n.dot(&n_face) > 0.5 {
            smooth += 1;
        }
        assert_eq!(geo.chart[i], a.chart_of_triangle[t]);
    }
    // Smooth normals stay within 60° of the face normal almost everywhere (marching-tetrahedra
    // slivers can tilt a face against its vertices' normals).
    assert!(
        smooth as f64 > 0.99 * geo.len() as f64,
        "{smooth} of {} texels",
        geo.len()
    );
    // The stricter utilisation counts exactly the texels whose centre is inside a triangle.
    let strict = inside as f64 / (a.width as f64 * a.height as f64);
    assert!(
        (strict - a.stats.inner_utilisation).abs() < 0.01,
        "{strict} vs {}",
        a.stats.inner_utilisation
    );
    // Every texel is listed once.
    let mut seen = vec![false; w * a.height as usize];
    for &t in &geo.texel {
        assert!(!seen[t as usize], "texel {t} listed twice");
        seen[t as usize] = true;
    }
}

#[test]
fn fill_pushes_colours_within_charts_and_into_the_gutter() {
    // 12x6 atlas: chart 0 in columns 0..4, gutter column 4..6, chart 1 in columns 6..10, chart 2
    // (never seen) in columns 10..12.
    let (w, h) = (12usize, 6usize);
    let chart: Vec<u32> = (0..w * h)
        .map(|i| match i % w {
            0..=3 => 0,
            4 | 5 => u32::MAX,
            6..=9 => 1,
            _ => 2,
        })
        .collect();
    let mut covered = vec![false; w * h];
    let mut rgb = vec![f32::NAN; 3 * w * h];
    let set = |x: usize, y: usize, c: [f32; 3], rgb: &mut [f32], covered: &mut [bool]| {
        covered[y * w + x] = true;
        rgb[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
    };
    set(0, 0, [1.0, 0.0, 0.0], &mut rgb, &mut covered);
    set(3, 5, [0.0, 1.0, 0.0], &mut rgb, &mut covered);
    set(9, 2, [0.0, 0.0, 1.0], &mut rgb, &mut covered);
    fill_uncovered(&mut rgb, w, h, &covered, &chart).unwrap();
    assert!(rgb.iter().all(|v| v.is_finite()), "a texel was left unset");
    for y in 0..h {
        for x in 0..w {
            let c = &rgb[3 * (y * w + x)..3 * (y * w + x) + 3];
            match chart[y * w + x] {
                // Chart 0 mixes only red and green: no blue from chart 1.
                0 => assert!(
                    c[2] == 0.0 && (c[0] + c[1] - 1.0).abs() < 1e-6,
                    "({x},{y}) {c:?}"
                ),
                1 => assert_eq!(c, [0.0, 0.0, 1.0]),
                // Never seen: the mean of the three measured colours.
                2 => assert!(c.iter().all(|&v| (v - 1.0 / 3.0).abs() < 1e-6), "{c:?}"),
                // Gutter: filled from its neighbours, values stay within [0, 1].
                _ => assert!(
                    c.iter().all(|&v| (0.0..=1.0).contains(&v)) && c.iter().sum::<f32>() > 0.0
                ),
            }
        }
    }
    // Near the red corner the fill is red, near the green corner green.
    assert_eq!(&rgb[3..6], &[1.0, 0.0, 0.0]);
    let i = 5 * w + 2;
    assert_eq!(&rgb[3 * i..3 * i + 3], &[0.0, 1.0, 0.0]);
    // Mismatched lengths are an error, not a panic.
    assert!(fill_uncovered(&mut rgb, w, h + 1, &covered, &chart).is_err());
}

#[test]
fn bad_inputs_are_errors() {
    let empty = TriMesh::default();
    assert!(build_atlas(&empty, &AtlasOptions::default()).is_err());
    let bad = TriMesh {
        positions: vec![Point3::origin(); 3],
        triangles: vec![[0, 1, 3]],
    };
    let e = build_atlas(&bad, &AtlasOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("triangle 0"), "{e}");
    let tri = TriMesh {
        positions: vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ],
        triangles: vec![[0, 1, 2]],
    };
    let opts = AtlasOptions {
        texel_mm: 0.0,
        ..Default::default()
    };
    assert!(build_atlas(&tri, &opts).is_err());
    let opts = AtlasOptions {
        max_chart_normal_angle_deg: 120.0,
        ..Default::default()
    };
    assert!(build_atlas(&tri, &opts).is_err());
    // A single triangle is a valid atlas; texels of another mesh are refused.
    let a = build_atlas(&tri, &AtlasOptions::default()).unwrap();
    assert_eq!(a.chart_count, 1);
    assert!((a.stats.mean_l2_stretch - 1.0).abs() < 1e-9);
    assert!(rasterize_texels(&a, &bad).is_err());
    let two = TriMesh {
        positions: tri.positions.clone(),
        triangles: vec![[0, 1, 2], [0, 2, 1]],
    };
    assert!(rasterize_texels(&a, &two).is_err());
}
