//! Chart segmentation: variational shape approximation (Cohen-Steiner et al. 2004, L2,1 metric on
//! face normals) grown over the face adjacency, plus the checks and local splits that make every
//! chart a topological disc with a bounded normal cone.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

use crate::math::Vector3;
use crate::mesh::TriMesh;

/// No neighbour across this edge (boundary, non-manifold or inconsistently wound).
pub(crate) const NONE: u32 = u32::MAX;

/// Per-face data the segmentation needs (f64, world mm).
pub(crate) struct FaceData {
    /// Unit face normals (zero for degenerate faces).
    pub normal: Vec<Vector3<f64>>,
    /// Face areas (mm²).
    pub area: Vec<f64>,
    /// Face centroids (mm).
    pub centroid: Vec<Vector3<f64>>,
    /// Neighbour face across edge k = (v[k], v[k+1]); [`NONE`] if there is none.
    pub adj: Vec<[u32; 3]>,
}

impl FaceData {
    /// Normals, areas, centroids and edge adjacency of `mesh`.
    pub fn new(mesh: &TriMesh) -> Self {
        let nt = mesh.triangles.len();
        let mut normal = Vec::with_capacity(nt);
        let mut area = Vec::with_capacity(nt);
        let mut centroid = Vec::with_capacity(nt);
        for t in &mesh.triangles {
            let p = t.map(|v| mesh.positions[v as usize].coords.cast::<f64>());
            let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
            let l = n.norm();
            normal.push(if l > 0.0 { n / l } else { Vector3::zeros() });
            area.push(0.5 * l);
            centroid.push((p[0] + p[1] + p[2]) / 3.0);
        }
        FaceData {
            normal,
            area,
            centroid,
            adj: adjacency(&mesh.triangles),
        }
    }
}

/// Edge adjacency. Only edges shared by exactly two faces that traverse them in opposite
/// directions connect faces: a chart must be an orientable manifold patch for LSCM.
fn adjacency(tris: &[[u32; 3]]) -> Vec<[u32; 3]> {
    use rayon::prelude::*;
    // (min vertex, max vertex, face*3+k, direction) sorted so that equal edges are adjacent.
    let mut edges: Vec<(u32, u32, u32, bool)> = Vec::with_capacity(tris.len() * 3);
    for (f, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.push((a.min(b), a.max(b), (f * 3 + k) as u32, a < b));
        }
    }
    edges.par_sort_unstable();
    let mut adj = vec![[NONE; 3]; tris.len()];
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 && edges[j].1 == edges[i].1 {
            j += 1;
        }
        if j - i == 2 && edges[i].3 != edges[i + 1].3 {
            let (ea, eb) = (edges[i].2 as usize, edges[i + 1].2 as usize);
            adj[ea / 3][ea % 3] = (eb / 3) as u32;
            adj[eb / 3][eb % 3] = (ea / 3) as u32;
        }
        i = j;
    }
    adj
}

/// A VSA proxy: the plane orientation a region approximates and its centre.
#[derive(Clone, Copy)]
struct Proxy {
    normal: Vector3<f64>,
    centre: Vector3<f64>,
}

impl Proxy {
    fn of_face(fd: &FaceData, f: u32) -> Self {
        Proxy {
            normal: fd.normal[f as usize],
            centre: fd.centroid[f as usize],
        }
    }

    /// Distortion of face `f` against the proxy: the L2,1 normal term plus a compactness term
    /// (squared distance to the centre times `compact`, mm⁻²) that keeps charts round rather
    /// than branching along the airway tree.
    fn error(&self, fd: &FaceData, f: usize, compact: f64) -> f64 {
        (fd.normal[f] - self.normal).norm_squared()
            + compact * (fd.centroid[f] - self.centre).norm_squared()
    }
}

/// Region-growing partition ("flooding" in VSA): faces of `faces` are claimed in order of
/// increasing `area * error` by proxies grown from `seeds`. Faces unreachable from any seed
/// start new proxies. Fills `label` (face → proxy) and returns the proxies.
fn flood(
    fd: &FaceData,
    member: &dyn Fn(usize) -> bool,
    faces: &[u32],
    seeds: &[u32],
    proxies: &[Proxy],
    compact: f64,
    label: &mut HashMap<u32, u32>,
) -> Vec<Proxy> {
    label.clear();
    let mut proxies: Vec<Proxy> = proxies.to_vec();
    let mut heap: BinaryHeap<Reverse<(u64, u32, u32)>> = BinaryHeap::new();
    let mut next_unseen = 0usize;
    let mut seeds: Vec<u32> = seeds.to_vec();
    loop {
        for (p, &s) in seeds.iter().enumerate() {
            let p = (proxies.len() - seeds.len() + p) as u32;
            heap.push(Reverse((0, s, p)));
        }
        while let Some(Reverse((_, f, p))) = heap.pop() {
            if label.contains_key(&f) {
                continue;
            }
            label.insert(f, p);
            for &g in &fd.adj[f as usize] {
                if g != NONE && member(g as usize) && !label.contains_key(&g) {
                    let e =
                        fd.area[g as usize] * proxies[p as usize].error(fd, g as usize, compact);
                    // Non-negative f64 bit patterns order like the values.
                    heap.push(Reverse((e.to_bits(), g, p)));
                }
            }
        }
        // A component without a seed gets its own proxy.
        while next_unseen < faces.len() && label.contains_key(&faces[next_unseen]) {
            next_unseen += 1;
        }
        if next_unseen == faces.len() {
            break;
        }
        let s = faces[next_unseen];
        proxies.push(Proxy::of_face(fd, s));
        seeds = vec![s];
    }
    proxies
}

/// Lloyd step: each region's area-weighted mean normal and centroid, and the face that fits
/// them best (the next seed). Regions that claimed nothing are dropped.
fn fit_proxies(
    fd: &FaceData,
    faces: &[u32],
    label: &HashMap<u32, u32>,
    n_proxies: usize,
    compact: f64,
) -> (Vec<u32>, Vec<Proxy>) {
    let mut sum = vec![(Vector3::zeros(), Vector3::zeros(), 0.0); n_proxies];
    for &f in faces {
        let s = &mut sum[label[&f] as usize];
        let a = fd.area[f as usize];
        s.0 += fd.normal[f as usize] * a;
        s.1 += fd.centroid[f as usize] * a;
        s.2 += a;
    }
    let proxies: Vec<Proxy> = sum
        .iter()
        .map(|(n, c, a)| Proxy {
            normal: n.try_normalize(0.0).unwrap_or_else(Vector3::z),
            centre: if *a > 0.0 { c / *a } else { *c },
        })
        .collect();
    let mut best = vec![(f64::INFINITY, NONE); n_proxies];
    for &f in faces {
        let p = label[&f] as usize;
        let d = proxies[p].error(fd, f as usize, compact);
        if d < best[p].0 {
            best[p] = (d, f);
        }
    }
    let keep: Vec<usize> = (0..n_proxies).filter(|&i| best[i].1 != NONE).collect();
    (
        keep.iter().map(|&i| best[i].1).collect(),
        keep.iter().map(|&i| proxies[i]).collect(),
    )
}

/// VSA over `faces` starting from `seeds`, with `iterations` Lloyd steps and compactness weight
/// `compact` (mm⁻²). Returns the regions, each connected over the face adjacency.
pub(crate) fn vsa(
    fd: &FaceData,
    faces: &[u32],
    seeds: &[u32],
    iterations: usize,
    compact: f64,
) -> Vec<Vec<u32>> {
    let all = faces.len() == fd.area.len();
    let set: std::collections::HashSet<u32> = if all {
        Default::default()
    } else {
        faces.iter().copied().collect()
    };
    let member = |f: usize| all || set.contains(&(f as u32));
    let mut label = HashMap::with_capacity(faces.len());
    let mut seeds = seeds.to_vec();
    let mut proxies: Vec<Proxy> = seeds.iter().map(|&s| Proxy::of_face(fd, s)).collect();
    for it in 0..=iterations {
        let grown = flood(fd, &member, faces, &seeds, &proxies, compact, &mut label);
        if it == iterations {
            let mut regions = vec![Vec::new(); grown.len()];
            for &f in faces {
                regions[label[&f] as usize].push(f);
            }
            regions.retain(|r| !r.is_empty());
            return regions;
        }
        (seeds, proxies) = fit_proxies(fd, faces, &label, grown.len(), compact);
    }
    unreachable!("the loop returns on its last iteration")
}

/// Area-weighted mean normal of a chart and the largest angle (rad) of a face normal from it.
pub(crate) fn normal_cone(fd: &FaceData, faces: &[u32]) -> (Vector3<f64>, f64, u32) {
    let mut s = Vector3::zeros();
    for &f in faces {
        s += fd.normal[f as usize] * fd.area[f as usize];
    }
    let n = s.try_normalize(0.0).unwrap_or_else(Vector3::z);
    let mut worst = (1.0f64, faces[0]);
    for &f in faces {
        if fd.area[f as usize] > 0.0 {
            let c = fd.normal[f as usize].dot(&n);
            if c < worst.0 {
                worst = (c, f);
            }
        }
    }
    (n, worst.0.clamp(-1.0, 1.0).acos(), worst.1)
}

/// True when the chart is a topological disc: Euler characteristic 1 and one boundary loop.
pub(crate) fn is_disc(tris: &[[u32; 3]], faces: &[u32]) -> bool {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 2);
    let mut verts: HashMap<u32, u32> = HashMap::with_capacity(faces.len());
    for &f in faces {
        let t = tris[f as usize];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            let n = verts.len() as u32;
            verts.entry(a).or_insert(n);
        }
    }
    let chi = verts.len() as i64 - edges.len() as i64 + faces.len() as i64;
    if chi != 1 {
        return false;
    }
    // Count boundary loops as connected components of the boundary-edge graph.
    let mut parent: Vec<u32> = (0..verts.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let mut on_boundary = vec![false; verts.len()];
    for (&(a, b), &c) in &edges {
        if c == 1 {
            let (a, b) = (verts[&a], verts[&b]);
            on_boundary[a as usize] = true;
            on_boundary[b as usize] = true;
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            parent[ra as usize] = rb;
        }
    }
    let loops = (0..verts.len() as u32)
        .filter(|&v| on_boundary[v as usize] && find(&mut parent, v) == v)
        .count();
    loops == 1
}

/// Split a chart in two: seeds at the face whose normal deviates most from the mean and at the
/// face farthest from it (in normal, then in space), grown by VSA. Returns `None` if the chart
/// cannot be split (a single face).
pub(crate) fn split(fd: &FaceData, faces: &[u32]) -> Option<Vec<Vec<u32>>> {
    if faces.len() < 2 {
        return None;
    }
    let (_, angle, a) = normal_cone(fd, faces);
    let regions = if angle > 1e-3 {
        let na = fd.normal[a as usize];
        let b = *faces
            .iter()
            .max_by(|&&x, &&y| {
                let dx = (fd.normal[x as usize] - na).norm_squared();
                let dy = (fd.normal[y as usize] - na).norm_squared();
                dx.total_cmp(&dy)
            })
            .expect("non-empty");
        if a == b {
            Vec::new()
        } else {
            vsa(fd, faces, &[a, b], 2, 0.0)
        }
    } else {
        Vec::new()
    };
    if regions.len() >= 2 {
        return Some(regions);
    }
    Some(split_spatial(fd, faces))
}

/// Split a flat chart by distance: breadth-first growth from the two centroids farthest apart.
fn split_spatial(fd: &FaceData, faces: &[u32]) -> Vec<Vec<u32>> {
    let far = |from: Vector3<f64>| {
        *faces
            .iter()
            .max_by(|&&x, &&y| {
                let dx = (fd.centroid[x as usize] - from).norm_squared();
                let dy = (fd.centroid[y as usize] - from).norm_squared();
                dx.total_cmp(&dy)
            })
            .expect("non-empty")
    };
    let a = far(fd.centroid[faces[0] as usize]);
    let b = far(fd.centroid[a as usize]);
    let set: std::collections::HashSet<u32> = faces.iter().copied().collect();
    let mut label: HashMap<u32, u32> = HashMap::with_capacity(faces.len());
    let mut heap = BinaryHeap::new();
    for (p, s) in [a, b].into_iter().enumerate() {
        heap.push(Reverse((0u64, s, p as u32)));
    }
    let seed_c = [fd.centroid[a as usize], fd.centroid[b as usize]];
    while let Some(Reverse((_, f, p))) = heap.pop() {
        if label.contains_key(&f) {
            continue;
        }
        label.insert(f, p);
        for &g in &fd.adj[f as usize] {
            if g != NONE && set.contains(&g) && !label.contains_key(&g) {
                let d = (fd.centroid[g as usize] - seed_c[p as usize]).norm();
                heap.push(Reverse((d.to_bits(), g, p)));
            }
        }
    }
    let mut out = vec![Vec::new(), Vec::new()];
    let mut rest = Vec::new();
    for &f in faces {
        match label.get(&f) {
            Some(&p) => out[p as usize].push(f),
            None => rest.push(f),
        }
    }
    // Faces not connected to either seed form their own charts, one per component.
    if !rest.is_empty() {
        let s = rest[0];
        out.extend(vsa(fd, &rest, &[s], 0, 0.0));
    }
    out.retain(|r| !r.is_empty());
    out
}
