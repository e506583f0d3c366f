//! Marching cubes, smoothing, decimation and mesh export: against scikit-image, analytic
//! surfaces, and the file formats' own structure.

use bronchosim::io::mesh_export::{read_ply, write_glb, write_obj, write_ply};
use bronchosim::math::{Affine, Matrix3, Point3, Vector3};
use bronchosim::mesh::decimate::{decimate, DecimateOptions};
use bronchosim::mesh::lumen::{lumen_mesh, LumenMeshOptions};
use bronchosim::mesh::metrics::{deviation, mesh_stats, signed_volume};
use bronchosim::mesh::smooth::{taubin, TaubinOptions};
use bronchosim::mesh::TriMesh;
use bronchosim::volume::{marching_cubes, Volume};
use std::collections::HashSet;

use bronchosim::rng::SplitMix64 as Rng;

/// Anisotropic grid, rotated about z, optionally mirrored (negative determinant).
fn affine(spacing: [f64; 3], mirrored: bool, origin: [f64; 3]) -> Affine {
    let (s, c) = (0.4f64.sin(), 0.4f64.cos());
    let rot = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    let mut lin = rot * Matrix3::from_diagonal(&Vector3::from(spacing));
    if mirrored {
        lin.column_mut(0).neg_mut();
    }
    let mut a = Affine::identity();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&lin);
    for k in 0..3 {
        a[(k, 3)] = origin[k];
    }
    a
}

/// CT-like volume: air (about −1040 HU) where `sdf` < 0, wall (+40) outside, a smooth 1 mm
/// transition centred on the surface, plus Gaussian noise of `noise` HU.
fn ct_volume(
    dims: [usize; 3],
    a: Affine,
    sdf: impl Fn(&Point3<f64>) -> f64,
    noise: f64,
    seed: u64,
) -> Volume<f32> {
    let mut v = Volume::filled(dims, a, 0f32);
    let mut rng = Rng::new(seed);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let w = v.index_to_world(Point3::new(i as f64, j as f64, k as f64));
                let hu = -500.0 + 540.0 * (sdf(&w) / 1.0).tanh() + noise * rng.normal();
                v.set(i, j, k, hu as f32);
            }
        }
    }
    v
}

/// The airway mask of a CT made by `ct_volume`: voxels half a millimetre inside the lumen.
fn airway_mask(ct: &Volume<f32>, sdf: impl Fn(&Point3<f64>) -> f64) -> Volume<u8> {
    let mut mask = Volume::filled(ct.dims, ct.affine, 0u8);
    for k in 0..ct.dims[2] {
        for j in 0..ct.dims[1] {
            for i in 0..ct.dims[0] {
                let w = ct.index_to_world(Point3::new(i as f64, j as f64, k as f64));
                mask.set(i, j, k, (sdf(&w) < -0.5) as u8);
            }
        }
    }
    mask
}

/// World position of the grid's centre.
fn grid_centre(dims: [usize; 3], a: Affine) -> Point3<f64> {
    let v = Volume::filled(dims, a, 0u8);
    v.index_to_world(Point3::new(
        (dims[0] - 1) as f64 / 2.0,
        (dims[1] - 1) as f64 / 2.0,
        (dims[2] - 1) as f64 / 2.0,
    ))
}

fn min_spacing(v: &Volume<f32>) -> f64 {
    v.spacing().iter().cloned().fold(f64::INFINITY, f64::min)
}

/// Directed-edge check: every undirected edge used by exactly two triangles, once each way.
fn assert_closed_and_oriented(m: &TriMesh) {
    let mut directed = HashSet::new();
    for t in &m.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            assert!(
                directed.insert((a, b)),
                "directed edge {a}->{b} used twice: inconsistent orientation or non-manifold"
            );
        }
    }
    for &(a, b) in &directed {
        assert!(
            directed.contains(&(b, a)),
            "edge {a}-{b} has no opposite: the mesh is open"
        );
    }
    let s = mesh_stats(m);
    assert_eq!((s.boundary_edges, s.non_manifold_edges), (0, 0));
}

#[test]
fn agrees_with_skimage_lorensen() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/mc_reference.json"
    ))
    .unwrap();
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    let dims: Vec<usize> = serde_json::from_value(r["dims_xyz"].clone()).unwrap();
    let spacing: Vec<f64> = serde_json::from_value(r["spacing_xyz"].clone()).unwrap();
    let data: Vec<f32> = serde_json::from_value(r["volume_x_fastest"].clone()).unwrap();
    let verts: Vec<[f64; 3]> = serde_json::from_value(r["verts_xyz_voxel"].clone()).unwrap();
    let faces: Vec<[usize; 3]> = serde_json::from_value(r["faces"].clone()).unwrap();
    let level = r["level"].as_f64().unwrap() as f32;
    // A mirrored, rotated, anisotropic affine: the comparison goes back through its inverse.
    let a = affine(
        [spacing[0], spacing[1], spacing[2]],
        true,
        [12.0, -40.0, 300.0],
    );
    let vol = Volume::from_data([dims[0], dims[1], dims[2]], a, data).unwrap();
    let mesh = marching_cubes(&vol, level, None).unwrap();
    assert_eq!(
        mesh.triangles.len(),
        faces.len(),
        "triangle count differs from skimage"
    );
    assert_eq!(
        mesh.positions.len(),
        verts.len(),
        "vertex count differs from skimage"
    );
    let ours: Vec<Point3<f64>> = mesh
        .positions
        .iter()
        .map(|p| vol.world_to_index(p.cast::<f64>()))
        .collect();
    // Nearest-neighbour matching, skimage → ours; must be a bijection.
    let mut map = vec![usize::MAX; verts.len()];
    let mut used = vec![false; ours.len()];
    let mut worst = 0f64;
    for (s, v) in verts.iter().enumerate() {
        let q = Point3::new(v[0], v[1], v[2]);
        let (best, d) = ours
            .iter()
            .enumerate()
            .map(|(n, p)| (n, (p - q).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        worst = worst.max(d);
        assert!(!used[best], "two skimage vertices match our vertex {best}");
        used[best] = true;
        map[s] = best;
    }
    assert!(worst < 1e-4, "largest vertex mismatch {worst} voxel");
    // Same triangles (as vertex sets) after matching.
    let key = |t: [usize; 3]| {
        let mut k = t;
        k.sort_unstable();
        k
    };
    let theirs: HashSet<[usize; 3]> = faces.iter().map(|f| key(f.map(|v| map[v]))).collect();
    let mine: HashSet<[usize; 3]> = mesh
        .triangles
        .iter()
        .map(|t| key(t.map(|v| v as usize)))
        .collect();
    assert_eq!(theirs, mine, "triangulations differ");
    println!(
        "skimage agreement: {} triangles, worst vertex {worst:.2e} voxel",
        faces.len()
    );
}

fn sphere_case(mirrored: bool) {
    let r = 6.0;
    let a = affine([0.6, 0.7, 0.9], mirrored, [-8.0, -13.0, -2.0]);
    let c = grid_centre([30, 28, 26], a) + Vector3::new(0.13, -0.21, 0.05);
    let vol = ct_volume([30, 28, 26], a, |p| (p - c).norm() - r, 0.0, 1);
    let mesh = marching_cubes(&vol, -500.0, None).unwrap();
    assert!(mesh.triangles.len() > 1000);
    assert_closed_and_oriented(&mesh);
    let mean = mesh
        .positions
        .iter()
        .map(|p| ((p.cast::<f64>() - c).norm() - r).abs())
        .sum::<f64>()
        / mesh.positions.len() as f64;
    let bound = 0.25 * min_spacing(&vol);
    println!(
        "sphere (mirrored {mirrored}): {} triangles, mean |d| {mean:.4} mm (bound {bound:.3})",
        mesh.triangles.len()
    );
    assert!(mean < bound, "mean distance {mean} mm over {bound}");
    // Normals face into the lumen: toward the centre.
    for t in 0..mesh.triangles.len() {
        let [p, q, s] = mesh.triangles[t].map(|v| mesh.positions[v as usize].cast::<f64>());
        let centroid = Point3::from((p.coords + q.coords + s.coords) / 3.0);
        let n = mesh.face_normal(t).cast::<f64>();
        assert!(
            n.dot(&(c - centroid)) > 0.0,
            "triangle {t} faces away from the lumen"
        );
    }
    // Inward normals make the divergence-theorem volume negative.
    let v = -signed_volume(&mesh);
    let truth = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
    assert!((v - truth).abs() / truth < 0.02, "volume {v} vs {truth}");
}

#[test]
fn sphere_is_accurate_closed_and_faces_inward_right_handed() {
    sphere_case(false);
}

#[test]
fn sphere_is_accurate_closed_and_faces_inward_mirrored() {
    sphere_case(true);
}

/// Oblique cylinder of radius `r` through `o` along unit `d`.
fn cyl_dist(p: &Point3<f64>, o: &Point3<f64>, d: &Vector3<f64>, r: f64) -> f64 {
    let rel = p - o;
    (rel - d * rel.dot(d)).norm() - r
}

#[test]
fn cylinder_is_accurate_and_open_only_at_the_grid_border() {
    let a = affine([0.5, 0.65, 0.8], true, [20.0, 5.0, -7.0]);
    let dims = [34, 30, 32];
    let vol0 = Volume::filled(dims, a, 0f32);
    let o = vol0.index_to_world(Point3::new(16.5, 14.5, 15.5));
    let d = Vector3::new(0.3, 0.2, 1.0).normalize();
    let r = 3.5;
    let vol = ct_volume(dims, a, |p| cyl_dist(p, &o, &d, r), 0.0, 2);
    let mesh = marching_cubes(&vol, -500.0, None).unwrap();
    let mean = mesh
        .positions
        .iter()
        .map(|p| cyl_dist(&p.cast(), &o, &d, r).abs())
        .sum::<f64>()
        / mesh.positions.len() as f64;
    let bound = 0.25 * min_spacing(&vol);
    println!(
        "cylinder: {} triangles, mean |d| {mean:.4} mm (bound {bound:.3})",
        mesh.triangles.len()
    );
    assert!(mean < bound);
    let s = mesh_stats(&mesh);
    assert_eq!(s.non_manifold_edges, 0);
    assert!(
        s.boundary_edges > 0,
        "the tube leaves the grid: the mesh must be open there"
    );
    // Every vertex of a boundary edge lies on the grid's border.
    let mut count = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for (p, q) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *count.entry((p.min(q), p.max(q))).or_insert(0) += 1;
        }
    }
    for (&(p, q), &n) in &count {
        if n == 1 {
            for v in [p, q] {
                let ijk = vol.world_to_index(mesh.positions[v as usize].cast());
                let on = (0..3).any(|ax| {
                    ijk[ax].abs() < 1e-3 || (ijk[ax] - (dims[ax] - 1) as f64).abs() < 1e-3
                });
                assert!(
                    on,
                    "boundary vertex {v} at index {ijk:?} is inside the grid"
                );
            }
        }
    }
    // Normals face the axis.
    for t in 0..mesh.triangles.len() {
        let [p, q, w] = mesh.triangles[t].map(|v| mesh.positions[v as usize].cast::<f64>());
        let cen = Point3::from((p.coords + q.coords + w.coords) / 3.0);
        let rel = cen - o;
        let radial = rel - d * rel.dot(&d);
        assert!(
            mesh.face_normal(t).cast::<f64>().dot(&radial) < 0.0,
            "triangle {t} faces outward"
        );
    }
}

#[test]
fn region_limits_the_surface_and_caps_it_closed() {
    let a = affine([0.8, 0.8, 0.8], false, [0.0, 0.0, 0.0]);
    let dims = [40, 24, 24];
    let vol0 = Volume::filled(dims, a, 0f32);
    let c1 = vol0.index_to_world(Point3::new(10.0, 11.5, 11.5));
    let c2 = vol0.index_to_world(Point3::new(29.0, 11.5, 11.5));
    let vol = ct_volume(
        dims,
        a,
        |p| ((p - c1).norm() - 5.0).min((p - c2).norm() - 5.0),
        0.0,
        3,
    );
    // Region: only the left half of the grid (the left sphere, and the right one not at all);
    // its edge at i = 12 cuts the left sphere, so the surface must be capped there, not opened.
    let mut region = Volume::filled(dims, a, 0u8);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..=12 {
                region.set(i, j, k, 1);
            }
        }
    }
    let mesh = marching_cubes(&vol, -500.0, Some(&region)).unwrap();
    assert_closed_and_oriented(&mesh);
    for p in &mesh.positions {
        let ijk = vol.world_to_index(p.cast());
        assert!(
            ijk.x <= 12.5 + 1e-4,
            "vertex at i = {} outside the region",
            ijk.x
        );
        assert!(
            (p.cast::<f64>() - c1).norm() < 5.0 + 0.8,
            "vertex far from the left sphere"
        );
    }
    let full = marching_cubes(&vol, -500.0, None).unwrap();
    assert!(full.triangles.len() > mesh.triangles.len());
}

#[test]
fn taubin_keeps_volume_and_reduces_noise() {
    let r = 7.0;
    let a = affine([0.7, 0.7, 0.9], true, [-11.0, -11.0, -11.0]);
    let c = grid_centre([32, 32, 26], a);
    let vol = ct_volume([32, 32, 26], a, |p| (p - c).norm() - r, 120.0, 4);
    let mc = marching_cubes(&vol, -500.0, None).unwrap();
    assert_closed_and_oriented(&mc);
    let err = |m: &TriMesh| {
        m.positions
            .iter()
            .map(|p| ((p.cast::<f64>() - c).norm() - r).abs())
            .sum::<f64>()
            / m.positions.len() as f64
    };
    let mut sm = mc.clone();
    taubin(&mut sm, &TaubinOptions::default()).unwrap();
    let (v0, v1) = (signed_volume(&mc), signed_volume(&sm));
    let shrink = (v0 - v1).abs() / v0.abs();
    let dev = deviation(&sm, &mc);
    println!(
        "taubin: volume change {:.3}%, mean |d| {:.4} -> {:.4} mm, deviation from MC mean {:.4} max {:.4} mm",
        100.0 * shrink,
        err(&mc),
        err(&sm),
        dev.mean_mm,
        dev.max_mm
    );
    assert!(shrink < 0.01, "volume changed by {:.3}%", 100.0 * shrink);
    assert!(
        err(&sm) < 0.8 * err(&mc),
        "smoothing should bring the noisy surface closer to the sphere"
    );
    assert!(dev.max_mm < 1.0 && dev.mean_mm > 0.0);
}

#[test]
fn decimation_reaches_target_edge_and_stays_manifold() {
    let r = 9.0;
    let a = affine([0.45, 0.5, 0.55], false, [-11.0, -11.0, -12.0]);
    let c = grid_centre([50, 46, 46], a);
    let vol = ct_volume([50, 46, 46], a, |p| (p - c).norm() - r, 30.0, 5);
    let mut mesh = marching_cubes(&vol, -500.0, None).unwrap();
    taubin(&mut mesh, &TaubinOptions::default()).unwrap();
    let opts = DecimateOptions::default();
    let (dec, rep) = decimate(&mesh, &opts).unwrap();
    let s0 = mesh_stats(&mesh);
    let s = mesh_stats(&dec);
    let dev = deviation(&mesh, &dec);
    let err = dec
        .positions
        .iter()
        .map(|p| ((p.cast::<f64>() - c).norm() - r).abs())
        .sum::<f64>()
        / dec.positions.len() as f64;
    println!(
        "decimate: {} -> {} triangles (target {}), edge mean {:.3} mm (was {:.3}), deviation mean {:.4} max {:.4} mm, \
         |d| to sphere {err:.4} mm, non-manifold before repair {}",
        rep.triangles_in, rep.triangles_out, rep.triangles_target, s.edge_mean_mm, s0.edge_mean_mm, dev.mean_mm, dev.max_mm,
        rep.non_manifold_before_repair
    );
    assert!(
        (s.edge_mean_mm - opts.target_edge_mm).abs() < 0.2 * opts.target_edge_mm,
        "mean edge {}",
        s.edge_mean_mm
    );
    assert_closed_and_oriented(&dec);
    assert!(
        dev.max_mm < opts.max_error_mm * 1.5,
        "decimation moved the surface by {} mm",
        dev.max_mm
    );
    assert!(err < 0.25 * 0.45);
}

#[test]
fn lumen_pipeline_on_a_tube_phantom_meets_the_accuracy_bound() {
    let a = affine([0.6, 0.6, 0.8], true, [30.0, -10.0, 5.0]);
    let dims = [48, 44, 40];
    let vol0 = Volume::filled(dims, a, 0f32);
    let o = vol0.index_to_world(Point3::new(23.5, 21.5, 19.5));
    let d = Vector3::new(0.2, -0.3, 1.0).normalize();
    let r = 5.0;
    // Lung-like parenchyma (−850 HU) beyond a 2 mm wall: it must not be meshed.
    let sdf = |p: &Point3<f64>| cyl_dist(p, &o, &d, r);
    let mut ct = ct_volume(dims, a, sdf, 25.0, 6);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let w = ct.index_to_world(Point3::new(i as f64, j as f64, k as f64));
                if sdf(&w) > 3.0 {
                    ct.set(i, j, k, -850.0);
                }
            }
        }
    }
    let mask = airway_mask(&ct, sdf);
    let (mesh, rep) = lumen_mesh(&ct, &mask, &LumenMeshOptions::default()).unwrap();
    let mean = mesh
        .positions
        .iter()
        .map(|p| cyl_dist(&p.cast(), &o, &d, r).abs())
        .sum::<f64>()
        / mesh.positions.len() as f64;
    println!("lumen pipeline: {}", serde_json::to_string(&rep).unwrap());
    println!("mean |d| to the true lumen {mean:.4} mm");
    assert!(mean < 0.25 * 0.6, "mean distance {mean} mm");
    assert!(rep.marching_cubes.triangles > rep.decimated.triangles);
    assert_eq!(rep.decimated.non_manifold_edges, 0);
    assert!(rep.smoothing_deviation.mean_mm > 0.0 && rep.decimation_deviation.mean_mm > 0.0);
}

#[test]
fn exports_round_trip_and_parse() {
    let a = affine([1.0, 1.0, 1.0], false, [-6.0, -6.0, -6.0]);
    let c = grid_centre([13, 13, 13], a);
    let vol = ct_volume([13, 13, 13], a, |p| (p - c).norm() - 4.0, 0.0, 7);
    let mesh = marching_cubes(&vol, -500.0, None).unwrap();
    let dir = tempfile::tempdir().unwrap();

    let ply = dir.path().join("m.ply");
    write_ply(&ply, &mesh).unwrap();
    let back = read_ply(&ply).unwrap();
    assert_eq!(back, mesh);

    let obj = dir.path().join("m.obj");
    let uvs: Vec<[f32; 2]> = mesh
        .positions
        .iter()
        .map(|p| [p.x * 0.01 + 0.5, p.y * 0.01 + 0.5])
        .collect();
    write_obj(&obj, &mesh, Some(&uvs)).unwrap();
    let text = std::fs::read_to_string(&obj).unwrap();
    let count = |tag: &str| text.lines().filter(|l| l.starts_with(tag)).count();
    assert_eq!(
        (count("v "), count("vn "), count("vt "), count("f ")),
        (
            mesh.positions.len(),
            mesh.positions.len(),
            mesh.positions.len(),
            mesh.triangles.len()
        )
    );
    let f0: Vec<u32> = text.lines().find(|l| l.starts_with("f ")).unwrap()[2..]
        .split_whitespace()
        .map(|s| s.split('/').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(f0, mesh.triangles[0].map(|v| v + 1).to_vec());

    // A 1x1 PNG: the GLB must embed it byte for byte.
    let png: Vec<u8> = {
        let mut buf = Vec::new();
        let mut enc = png::Encoder::new(&mut buf, 1, 1);
        enc.set_color(png::ColorType::Rgb);
        enc.write_header()
            .unwrap()
            .write_image_data(&[200, 120, 110])
            .unwrap();
        buf
    };
    for tex in [None, Some((uvs.as_slice(), png.as_slice()))] {
        let glb = dir.path().join("m.glb");
        write_glb(&glb, &mesh, tex).unwrap();
        let bytes = std::fs::read(&glb).unwrap();
        let u32at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
        assert_eq!(&bytes[0..4], b"glTF");
        assert_eq!(u32at(4), 2);
        assert_eq!(u32at(8), bytes.len());
        let jlen = u32at(12);
        assert_eq!(&bytes[16..20], b"JSON");
        let js: serde_json::Value = serde_json::from_slice(&bytes[20..20 + jlen]).unwrap();
        let bin_at = 20 + jlen;
        assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
        let bin = &bytes[bin_at + 8..bin_at + 8 + u32at(bin_at)];
        assert_eq!(
            js["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
            bin.len()
        );
        let prim = &js["meshes"][0]["primitives"][0];
        let acc = |i: &serde_json::Value| &js["accessors"][i.as_u64().unwrap() as usize];
        assert_eq!(
            acc(&prim["attributes"]["POSITION"])["count"]
                .as_u64()
                .unwrap() as usize,
            mesh.positions.len()
        );
        assert_eq!(
            acc(&prim["attributes"]["NORMAL"])["count"]
                .as_u64()
                .unwrap() as usize,
            mesh.positions.len()
        );
        assert_eq!(
            acc(&prim["indices"])["count"].as_u64().unwrap() as usize,
            3 * mesh.triangles.len()
        );
        let min = acc(&prim["attributes"]["POSITION"])["min"][0]
            .as_f64()
            .unwrap() as f32;
        assert_eq!(
            min,
            mesh.positions
                .iter()
                .map(|p| p.x)
                .fold(f32::INFINITY, f32::min)
        );
        // The index buffer holds our triangles.
        let iv = &js["bufferViews"][acc(&prim["indices"])["bufferView"].as_u64().unwrap() as usize];
        let off = iv["byteOffset"].as_u64().unwrap() as usize;
        let first: Vec<u32> = (0..3)
            .map(|k| u32::from_le_bytes(bin[off + 4 * k..off + 4 * k + 4].try_into().unwrap()))
            .collect();
        assert_eq!(first, mesh.triangles[0].to_vec());
        assert!(gltf_json::Root::from_slice(&bytes[20..20 + jlen]).is_ok());
        if tex.is_some() {
            assert!(prim["attributes"]["TEXCOORD_0"].is_u64());
            let view = &js["bufferViews"][js["images"][0]["bufferView"].as_u64().unwrap() as usize];
            let o = view["byteOffset"].as_u64().unwrap() as usize;
            assert_eq!(&bin[o..o + png.len()], png.as_slice());
        } else {
            assert!(js.get("images").is_none());
        }
    }
    // No temporary files are left beside the outputs.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

/// Cartilage-ring relief (0.3 mm deep, 4 mm apart) on a tube in a 0.7 x 0.7 x 1.0 mm CT with
/// 20 HU noise: Taubin smoothing alone flattens the rings; projecting the smoothed vertices
/// back onto the CT's iso-surface (`iso_snap_mm`, on by default) keeps them.
#[test]
fn iso_snap_keeps_the_ring_relief_that_smoothing_flattens() {
    let a = affine([0.7, 0.7, 1.0], false, [0.0, 0.0, 0.0]);
    let dims = [36, 36, 44];
    let vol0 = Volume::filled(dims, a, 0f32);
    let o = vol0.index_to_world(Point3::new(17.5, 17.5, 21.5));
    let d = Vector3::new(0.0, 0.15, 1.0).normalize();
    let (r0, amp, period) = (6.0, 0.3, 4.0);
    let k = std::f64::consts::TAU / period;
    let axial = |p: &Point3<f64>| (p - o).dot(&d);
    let radial = |p: &Point3<f64>| {
        let v = p - o;
        (v - d * v.dot(&d)).norm()
    };
    // Positive in the wall: distance beyond the ringed radius.
    let sdf = |p: &Point3<f64>| radial(p) - (r0 + amp * (k * axial(p)).cos());
    let ct = ct_volume(dims, a, sdf, 20.0, 11);
    let mask = airway_mask(&ct, sdf);
    // Ring amplitude: least squares radial = c + a cos(k s) + b sin(k s) over vertices away
    // from the ends; and the mean distance to the true surface.
    let measure = |snap: f64| {
        let opts = LumenMeshOptions {
            iso_snap_mm: snap,
            ..Default::default()
        };
        let (mesh, _) = lumen_mesh(&ct, &mask, &opts).unwrap();
        let (mut ata, mut atb) = (nalgebra::Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
        let (mut dist, mut n) = (0.0, 0usize);
        for p in &mesh.positions {
            let p: Point3<f64> = p.cast();
            let s = axial(&p);
            if s.abs() > 14.0 || radial(&p) < r0 - 2.0 {
                continue;
            }
            let row = Vector3::new(1.0, (k * s).cos(), (k * s).sin());
            ata += row * row.transpose();
            atb += row * radial(&p);
            dist += sdf(&p).abs();
            n += 1;
        }
        let x = ata.lu().solve(&atb).unwrap();
        ((x[1] * x[1] + x[2] * x[2]).sqrt(), dist / n as f64, n)
    };
    let (amp_smooth, dist_smooth, n) = measure(0.0);
    let (amp_snap, dist_snap, _) = measure(LumenMeshOptions::default().iso_snap_mm);
    println!(
        "ring amplitude (true {amp} mm) over {n} vertices: Taubin {amp_smooth:.3} mm (mean |d| \
         {dist_smooth:.4}), Taubin + iso snap {amp_snap:.3} mm (mean |d| {dist_snap:.4})"
    );
    assert!(amp_snap > 0.8 * amp, "snapped ring amplitude {amp_snap}");
    assert!(amp_snap > amp_smooth + 0.02, "{amp_snap} vs {amp_smooth}");
    assert!(dist_snap < dist_smooth, "{dist_snap} vs {dist_smooth}");
}
