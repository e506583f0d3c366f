//! De-lighting and fusion (paper §2.4) end to end on a synthetic airway with a known albedo;
//! occlusion; outputs.

#![allow(clippy::needless_range_loop)]

mod texture_support;

use std::sync::OnceLock;

use bronchosim::camera::Camera;
use bronchosim::image::Frame;
use bronchosim::math::{Affine, Point3};
use bronchosim::mesh::TriMesh;
use bronchosim::raycast::{cast_frame, Scene};
use bronchosim::shading::{ExclusionCounts, FrameShading, PsiModel};
use bronchosim::texture::atlas::{build_atlas, rasterize_texels, AtlasOptions};
use bronchosim::texture::{
    delight_frame, fuse, write_texture_outputs, DelightOptions, FusedTexture, FusionMethod,
    FusionOptions, Observation, TexelSet,
};
use texture_support::{albedo, look, Shot, World};

const FRAMES: usize = 12;

fn world() -> &'static (World, Vec<Shot>) {
    static CELL: OnceLock<(World, Vec<Shot>)> = OnceLock::new();
    CELL.get_or_init(|| {
        let w = World::new(1.0, 0.2, 256);
        let shots: Vec<Shot> = World::poses(FRAMES)
            .iter()
            .enumerate()
            .map(|(i, p)| w.shoot(p, 100 + i as u64))
            .collect();
        eprintln!(
            "scene: {}x{} atlas, {} chart texels, {} frames",
            w.atlas.width,
            w.atlas.height,
            w.texels.len(),
            shots.len()
        );
        (w, shots)
    })
}

fn run(method: FusionMethod, frames: usize) -> FusedTexture {
    let (w, shots) = world();
    let mut obs: Vec<Observation> = shots[..frames]
        .iter()
        .map(|s| s.observation(&w.camera))
        .collect();
    let opts = FusionOptions {
        method,
        ..Default::default()
    };
    fuse(&w.texels, obs.as_mut_slice(), &opts).expect("fuse")
}

/// Per covered slot: (slot, atlas index, fused, truth).
fn pairs(f: &FusedTexture, texels: &TexelSet) -> Vec<(usize, usize, [f64; 3], [f64; 3])> {
    (0..texels.len())
        .filter_map(|s| {
            let t = texels.texel[s] as usize;
            f.covered[t].then(|| {
                let v = [0, 1, 2].map(|c| f.rgb[3 * t + c] as f64);
                (s, t, v, albedo(texels.point[s].map(f64::from)))
            })
        })
        .collect()
}

/// Least-squares scale per channel mapping fused onto truth.
fn scales(p: &[(usize, usize, [f64; 3], [f64; 3])]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        let num: f64 = p.iter().map(|x| x.2[c] * x.3[c]).sum();
        let den: f64 = p.iter().map(|x| x.2[c] * x.2[c]).sum();
        num / den
    })
}

/// Relative RMS error `sqrt(sum |s v - a|^2 / sum |a|^2)` over the entries of `p` selected.
fn rel_rms(
    p: &[(usize, usize, [f64; 3], [f64; 3])],
    s: [f64; 3],
    keep: impl Fn(usize) -> bool,
) -> f64 {
    let (mut e, mut a) = (0.0, 0.0);
    for x in p.iter().filter(|x| keep(x.0)) {
        for c in 0..3 {
            e += (s[c] * x.2[c] - x.3[c]).powi(2);
            a += x.3[c].powi(2);
        }
    }
    (e / a).sqrt()
}

/// Texels whose true albedo differs from a 4-neighbour of the same chart (vessel edges).
fn edge_slots(texels: &TexelSet) -> Vec<bool> {
    let w = texels.width as usize;
    let truth: Vec<[f64; 3]> = texels
        .point
        .iter()
        .map(|p| albedo(p.map(f64::from)))
        .collect();
    (0..texels.len())
        .map(|s| {
            let t = texels.texel[s] as usize;
            let (x, y) = (t % w, t / w);
            let nb = [
                (x + 1, y),
                (x.wrapping_sub(1), y),
                (x, y + 1),
                (x, y.wrapping_sub(1)),
            ];
            nb.iter().any(|&(nx, ny)| {
                if nx >= w || ny >= texels.height as usize {
                    return false;
                }
                let q = texels.slot_of_texel[ny * w + nx];
                q != u32::MAX
                    && texels.chart[q as usize] == texels.chart[s]
                    && (truth[q as usize][1] - truth[s][1]).abs() > 0.1 * truth[s][1]
            })
        })
        .collect()
}

/// Mean squared difference between horizontally / vertically adjacent covered texels of the
/// same chart (green channel, after scaling): high for sharp vessel edges.
fn gradient_energy(f: &FusedTexture, texels: &TexelSet, s: f64) -> f64 {
    let w = texels.width as usize;
    let (mut e, mut n) = (0.0, 0usize);
    for i in 0..texels.len() {
        let t = texels.texel[i] as usize;
        if !f.covered[t] {
            continue;
        }
        for u in [t + 1, t + w] {
            if u >= f.covered.len() || !f.covered[u] || (u == t + 1 && u % w == 0) {
                continue;
            }
            let q = texels.slot_of_texel[u];
            if q == u32::MAX || texels.chart[q as usize] != texels.chart[i] {
                continue;
            }
            e += (s * (f.rgb[3 * u + 1] - f.rgb[3 * t + 1]) as f64).powi(2);
            n += 1;
        }
    }
    e / n as f64
}

#[test]
fn fused_albedo_matches_truth_and_nms_is_sharper() {
    let (w, _) = world();
    let nms = run(
        FusionMethod::MaxWeightSmoothed { sigma_texels: 2.0 },
        FRAMES,
    );
    let avg = run(
        FusionMethod::WeightedAverage {
            weight_exponent: 1.0,
        },
        FRAMES,
    );
    // The same texels are covered by both methods (coverage does not depend on the blend).
    assert_eq!(nms.covered, avg.covered);
    let covered = nms.stats.covered_texels;
    assert!(
        covered as f64 > 0.25 * w.texels.len() as f64,
        "only {covered} of {} texels covered",
        w.texels.len()
    );
    let pn = pairs(&nms, &w.texels);
    let pa = pairs(&avg, &w.texels);
    let (sn, sa) = (scales(&pn), scales(&pa));
    let err_n = rel_rms(&pn, sn, |_| true);
    let err_a = rel_rms(&pa, sa, |_| true);
    let edges = edge_slots(&w.texels);
    let edge_n = rel_rms(&pn, sn, |s| edges[s]);
    let edge_a = rel_rms(&pa, sa, |s| edges[s]);
    let truth = {
        // Truth in the same layout, for its gradient energy.
        let mut t = nms.clone();
        for s in 0..w.texels.len() {
            let a = albedo(w.texels.point[s].map(f64::from));
            let i = w.texels.texel[s] as usize;
            for c in 0..3 {
                t.rgb[3 * i + c] = a[c] as f32;
            }
        }
        t
    };
    let (gn, ga, gt) = (
        gradient_energy(&nms, &w.texels, sn[1]),
        gradient_energy(&avg, &w.texels, sa[1]),
        gradient_energy(&truth, &w.texels, 1.0),
    );
    eprintln!(
        "covered {covered}/{} texels; relative RMS: NMS+smooth {err_n:.4}, weighted average \
         {err_a:.4}; at vessel edges: {edge_n:.4} vs {edge_a:.4}; gradient energy (x1e4) \
         NMS {:.3}, average {:.3}, truth {:.3}; scales NMS {sn:?}",
        w.texels.len(),
        gn * 1e4,
        ga * 1e4,
        gt * 1e4
    );
    // Measured here: NMS+smooth 0.18, weighted average 0.13. The error is dominated by Psi's
    // misfit of the physically based light (cone, 1/z^2 over a 7-60 mm depth range), not by
    // the de-lighting: the 10% aim of issue 6 is not met on this scene (see the report).
    assert!(err_n < 0.22, "relative RMS error {err_n}");
    assert!(err_a < 0.17, "weighted-average relative RMS error {err_a}");
    // The paper's observation: suppressing non-maximal weights keeps vessel edges sharp.
    assert!(gn > ga, "gradient energy NMS {gn} vs average {ga}");
    assert!(
        gn < 1.2 * gt,
        "gradient energy NMS {gn} vs truth {gt}: noise, not sharpness"
    );
    // Frames seen: every covered texel was seen by at least one frame.
    assert!(nms
        .covered
        .iter()
        .zip(&nms.frames_seen)
        .all(|(&c, &n)| !c || n >= 1));
}

#[test]
fn fusion_state_does_not_grow_with_frames() {
    let a = run(FusionMethod::MaxWeightSmoothed { sigma_texels: 2.0 }, 4);
    let b = run(
        FusionMethod::MaxWeightSmoothed { sigma_texels: 2.0 },
        FRAMES,
    );
    let c = run(
        FusionMethod::WeightedAverage {
            weight_exponent: 1.0,
        },
        4,
    );
    let d = run(
        FusionMethod::WeightedAverage {
            weight_exponent: 1.0,
        },
        FRAMES,
    );
    assert_eq!(a.stats.state_bytes, b.stats.state_bytes);
    assert_eq!(c.stats.state_bytes, d.stats.state_bytes);
    assert!(b.stats.covered_texels > a.stats.covered_texels);
    // O(texels): a few dozen bytes per texel.
    assert!(b.stats.state_bytes <= 40 * b.stats.chart_texels);
}

#[test]
fn single_frame_delighting_agrees_with_fusion_of_that_frame() {
    let (w, shots) = world();
    let obs = shots[3].observation(&w.camera);
    let d = delight_frame(&w.texels, &obs, &DelightOptions::default()).expect("delight");
    let mut one = vec![obs];
    let f = fuse(&w.texels, one.as_mut_slice(), &FusionOptions::default()).expect("fuse");
    assert_eq!(d.observed(), f.stats.covered_texels);
    for s in 0..w.texels.len() {
        let t = w.texels.texel[s] as usize;
        if d.weight[s] > 0.0 {
            for c in 0..3 {
                assert!(
                    (d.value[s][c] - f.rgb[3 * t + c]).abs() <= 1e-5 * d.value[s][c].abs().max(1.0)
                );
            }
        }
    }
}

/// A square plate of half-size `half` (mm) at depth `z`, facing -z (towards a camera at the origin).
fn plate(mesh: &mut TriMesh, half: f32, z: f32, n: usize) {
    let base = mesh.positions.len() as u32;
    for j in 0..=n {
        for i in 0..=n {
            let x = -half + 2.0 * half * i as f32 / n as f32;
            let y = -half + 2.0 * half * j as f32 / n as f32;
            mesh.positions.push(Point3::new(x, y, z));
        }
    }
    let id = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            // (b - a) x (c - a) points to -z.
            mesh.triangles.push([id(i, j), id(i, j + 1), id(i + 1, j)]);
            mesh.triangles
                .push([id(i + 1, j), id(i, j + 1), id(i + 1, j + 1)]);
        }
    }
}

#[test]
fn occluded_texels_take_nothing_from_the_frame() {
    let mut mesh = TriMesh {
        positions: Vec::new(),
        triangles: Vec::new(),
    };
    plate(&mut mesh, 20.0, 30.0, 20); // back wall, albedo 0.8
    plate(&mut mesh, 5.0, 15.0, 5); // occluder, albedo 0.2
    assert!(mesh.face_normal(0).z < 0.0);
    let atlas = build_atlas(
        &mesh,
        &AtlasOptions {
            texel_mm: 0.25,
            ..Default::default()
        },
    )
    .expect("atlas");
    let texels = TexelSet::new(&rasterize_texels(&atlas, &mesh).expect("texels")).expect("set");
    let camera = Camera {
        width: 200,
        height: 200,
        fx: 100.0,
        fy: 100.0,
        cx: 99.5,
        cy: 99.5,
        k1: -0.05,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    };
    let pose: Affine = look([0.0; 3], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]);
    let g = cast_frame(&Scene::new(&mesh).expect("scene"), &camera, &pose);
    let mut frame = Frame::new(200, 200);
    for i in 0..200 * 200 {
        if g.hit(i) {
            let a = if g.point[i][2] < 20.0 { 0.2 } else { 0.8 };
            frame.rgb[3 * i..3 * i + 3].copy_from_slice(&[a; 3]);
        }
    }
    // Psi = 1 everywhere (rho = sum of the Bernstein basis = 1, varrho = 1): de-lit = pixel.
    let psi = PsiModel {
        camera_to_world: [0.0; 16],
        z_min: 10.0,
        z_max: 40.0,
        c: [[1.0; 4]; 3],
        d: [[1.0; 3]; 3],
        rms_residual: [0.0; 3],
        samples_used: 0,
        excluded: ExclusionCounts::default(),
    };
    let mut obs = vec![Observation {
        frame: &frame,
        camera: &camera,
        camera_to_world: &pose,
        shading: FrameShading::Paper(&psi),
        depth: &g.z,
    }];
    let f = fuse(&texels, obs.as_mut_slice(), &FusionOptions::default()).expect("fuse");
    let (mut hidden, mut hidden_covered, mut visible, mut visible_covered) = (0, 0, 0, 0);
    let mut worst_back = 1.0f32;
    for s in 0..texels.len() {
        let p = texels.point[s];
        let t = texels.texel[s] as usize;
        let v = f.rgb[3 * t + 1];
        if p[2] > 25.0 {
            // The occluder's shadow on the back wall (seen from the origin) has half-size 10 mm.
            let m = p[0].abs().max(p[1].abs());
            if m < 9.5 {
                hidden += 1;
                hidden_covered += f.covered[t] as usize;
            } else if m > 10.5 && m < 19.5 {
                visible += 1;
                visible_covered += f.covered[t] as usize;
            }
            if f.covered[t] {
                worst_back = worst_back.min(v);
            }
        } else if f.covered[t] {
            assert!((v - 0.2).abs() < 1e-3, "occluder texel {v}");
        }
    }
    eprintln!(
        "occlusion: {hidden_covered}/{hidden} hidden texels covered, {visible_covered}/{visible} \
         visible; darkest covered back-wall texel {worst_back}"
    );
    assert!(hidden > 1000 && visible > 1000);
    assert_eq!(hidden_covered, 0);
    assert!(visible_covered as f64 > 0.99 * visible as f64);
    // No back-wall texel picked up the occluder's colour at its silhouette.
    assert!(
        (worst_back - 0.8).abs() < 1e-3,
        "darkest back-wall texel {worst_back}"
    );
}

#[test]
fn outputs_are_written_and_uvs_address_the_albedo() {
    let (w, _) = world();
    let f = run(
        FusionMethod::MaxWeightSmoothed { sigma_texels: 2.0 },
        FRAMES,
    );
    let filled = f.filled(&w.texels).expect("fill");
    assert!(filled.iter().all(|v| v.is_finite() && *v >= 0.0));
    let dir = tempfile::tempdir().expect("tmp");
    let out = write_texture_outputs(dir.path(), &w.atlas, &filled, &f.covered).expect("write");
    assert_eq!(out.covered_texels, f.stats.covered_texels);
    let albedo_png = bronchosim::io::png::read_png(&dir.path().join("albedo.png")).expect("png");
    assert_eq!(
        (albedo_png.width, albedo_png.height),
        (w.atlas.width, w.atlas.height)
    );
    // The PNG holds the fused atlas times the recorded scale, row y = 0 first: check a covered texel.
    let t = (0..f.covered.len())
        .find(|&i| f.covered[i])
        .expect("a covered texel");
    for c in 0..3 {
        let want = (f.rgb[3 * t + c] * out.albedo_scale).min(1.0);
        let got = albedo_png.rgb[3 * t + c];
        assert!((got - want).abs() < 0.01 + 0.02 * want, "{got} vs {want}");
    }
    let cov = bronchosim::io::png::read_png(&dir.path().join("coverage.png")).expect("png");
    let n_cov = cov.rgb.chunks(3).filter(|p| p[0] > 0.5).count();
    assert_eq!(n_cov, f.stats.covered_texels);
    let glb = std::fs::read(dir.path().join("airway.glb")).expect("glb");
    assert_eq!(&glb[0..4], b"glTF");
    // The embedded image is the albedo PNG.
    let png = std::fs::read(dir.path().join("albedo.png")).expect("png");
    assert!(glb.windows(png.len().min(64)).any(|x| x == &png[..64]));
}

/// The default `min_relative_weight` (0.05): texels lit at under 5% of the frame's brightest
/// prediction are where the shading is least reliable, and dropping them cuts the albedo error
/// several-fold while keeping more coverage than a stricter threshold. Measured (relative RMS
/// error / covered texels, max-weight and average fusion): 0 -> 0.620 / 0.578 over 151,689;
/// 0.02 -> 0.266 / 0.236 over 118,995; 0.05 -> 0.180 / 0.131 over 90,005; 0.1 -> 0.180 / 0.131
/// over 81,296; 0.2 -> 0.180 / 0.139 over 73,924.
#[test]
fn default_light_threshold_drops_unreliable_texels_and_keeps_coverage() {
    let (w, shots) = world();
    let default = FusionOptions::default().delight.min_relative_weight;
    assert_eq!(default, 0.05);
    for method in [
        FusionMethod::MaxWeightSmoothed { sigma_texels: 2.0 },
        FusionMethod::WeightedAverage {
            weight_exponent: 1.0,
        },
    ] {
        let run = |thr: f64| {
            let mut obs: Vec<Observation> =
                shots.iter().map(|s| s.observation(&w.camera)).collect();
            let mut opts = FusionOptions {
                method,
                ..Default::default()
            };
            opts.delight.min_relative_weight = thr;
            let f = fuse(&w.texels, obs.as_mut_slice(), &opts).unwrap();
            let p = pairs(&f, &w.texels);
            let sc = scales(&p);
            (rel_rms(&p, sc, |_| true), f.stats.covered_texels)
        };
        let (none, chosen, strict) = (run(0.0), run(default), run(0.2));
        println!(
            "{method:?}: error / coverage without {none:?}, default {chosen:?}, 0.2 {strict:?}"
        );
        assert!(chosen.0 < 0.4 * none.0, "{chosen:?} vs {none:?}");
        assert!(chosen.0 < strict.0 + 0.01, "{chosen:?} vs {strict:?}");
        assert!(
            chosen.1 as f64 > 1.15 * strict.1 as f64,
            "{chosen:?} vs {strict:?}"
        );
    }
}
