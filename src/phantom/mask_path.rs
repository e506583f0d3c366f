//! A camera centreline through a real binary airway mask: from the top of the trachea, past
//! the carina into the left main bronchus, then into the lower-lobe bronchus.
//!
//! Steps: keep the component of the thickest voxel; exact distance transforms inside and
//! outside give a signed distance to the wall; the start is the most central voxel in the top
//! 3 mm of the tree (splits closer than 12 mm to it are ignored: the wavefront there still
//! has a piece running up). A Dijkstra on voxel lengths (26-neighbours) orders the tree by geodesic
//! depth; sweeping that depth in shells (~2 mm) and counting connected pieces per shell finds
//! each split: at the carina the branch on the patient's left (-x in RAS) is kept, at the next
//! split the lower one (smaller z), then the thicker one, up to 20 mm past the lobar split.
//! The target is the most central voxel there, and a second Dijkstra with the cost
//! `length / (dt + 0.5)²` gives the path that hugs the centre of the lumen.

use crate::math::Point3;
use crate::mesh::GeometryError;
use crate::volume::geodesic::{centred_path, dijkstra, inside_distance, neighbours, step};
use crate::volume::morphology::{component_of, distance_transform_sq};
use crate::volume::Volume;
use crate::volume::VolumeError;
use crate::Result;

/// The centreline through a mask and the signed distance it was found with.
#[derive(Clone, Debug)]
pub struct MaskCentreline {
    /// Voxel-centre polyline from 15 mm below the trachea's top to the target (world mm),
    /// unsmoothed.
    pub points: Vec<Point3<f64>>,
    /// Signed distance to the lumen wall (mm, negative inside), on the mask's grid.
    pub sdf: Volume<f32>,
    /// Geodesic depth (mm) of the carina and of the lobar split along the path.
    pub split_depths_mm: Vec<f64>,
}

/// Find the camera centreline through `mask` (nonzero = lumen); see the module docs.
pub fn mask_centreline(mask: &Volume<u8>) -> Result<MaskCentreline> {
    let dt_in = inside_distance(mask);
    let comp = thickest_component(mask, &dt_in)?;
    let sdf = signed_distance(&comp, &dt_in)?;
    let start = top_start(&comp, &dt_in);
    let sweep = sweep_shells(&comp, &dt_in, start);
    if sweep.splits.len() < 2 {
        return Err(GeometryError::Degenerate {
            stage: "mask centreline",
            message: format!(
                "found {} of the two expected splits (carina, lobar) below the top",
                sweep.splits.len()
            ),
        }
        .into());
    }
    let target = sweep
        .target
        .or_else(|| best_of(&sweep.last_active, &dt_in))
        .ok_or(VolumeError::Empty {
            stage: "mask centreline",
            what: "set of target voxels",
        })?;
    // Centred path: cost length / (dt + 0.5)², averaged over the edge's two voxels.
    let chain = centred_path(&comp, &dt_in, start, target)?;
    // The first 15 mm are dropped: segmentations often taper at the cut top of the trachea.
    let pts: Vec<Point3<f64>> = chain.into_iter().map(|i| voxel_world(&comp, i)).collect();
    let mut arc = 0.0;
    let mut first = 0;
    for k in 1..pts.len() {
        arc += (pts[k] - pts[k - 1]).norm();
        if arc >= 15.0 {
            first = k;
            break;
        }
    }
    Ok(MaskCentreline {
        points: pts[first..].to_vec(),
        sdf,
        split_depths_mm: sweep.splits,
    })
}

/// The connected component of `mask` that holds its thickest voxel (largest inside distance
/// `dt_in`, mm; the first one on ties).
fn thickest_component(mask: &Volume<u8>, dt_in: &[f32]) -> Result<Volume<u8>> {
    let dims = mask.dims;
    let (thick, &best) = dt_in
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))
        .ok_or(VolumeError::Empty {
            stage: "mask centreline",
            what: "mask",
        })?;
    if best <= 0.0 || best.is_infinite() {
        return Err(VolumeError::Empty {
            stage: "mask centreline",
            what: "lumen (no voxel inside the mask's wall)",
        }
        .into());
    }
    let seed = [
        thick % dims[0],
        (thick / dims[0]) % dims[1],
        thick / (dims[0] * dims[1]),
    ];
    Ok(component_of(mask, seed))
}

/// Signed distance to the wall of `comp` (mm, negative inside): the inside distance `dt_in`
/// or the outside one, shifted by half a mean voxel so the zero lies between voxel centres.
fn signed_distance(comp: &Volume<u8>, dt_in: &[f32]) -> Result<Volume<f32>> {
    let sp = comp.spacing();
    let dt_out: Vec<f32> = distance_transform_sq(comp.dims, sp, |i| comp.data[i] != 0)
        .into_iter()
        .map(f32::sqrt)
        .collect();
    let half = ((sp[0] + sp[1] + sp[2]) / 6.0) as f32;
    let sdf_data: Vec<f32> = (0..comp.len())
        .map(|i| {
            if comp.data[i] != 0 {
                half - dt_in[i]
            } else {
                dt_out[i] - half
            }
        })
        .collect();
    Volume::from_data(comp.dims, comp.affine, sdf_data)
}

/// World position (mm) of the centre of voxel `i` (linear index).
fn voxel_world(grid: &Volume<u8>, i: usize) -> Point3<f64> {
    let dims = grid.dims;
    grid.index_to_world(Point3::new(
        (i % dims[0]) as f64,
        ((i / dims[0]) % dims[1]) as f64,
        (i / (dims[0] * dims[1])) as f64,
    ))
}

/// World height z (mm) of the centre of voxel `i` (linear index).
fn voxel_z(grid: &Volume<u8>, i: usize) -> f64 {
    let (a, dims) = (&grid.affine, grid.dims);
    a[(2, 0)] * (i % dims[0]) as f64
        + a[(2, 1)] * ((i / dims[0]) % dims[1]) as f64
        + a[(2, 2)] * (i / (dims[0] * dims[1])) as f64
        + a[(2, 3)]
}

/// The start: the most central voxel of the component's top 3 mm.
fn top_start(comp: &Volume<u8>, dt_in: &[f32]) -> usize {
    let members: Vec<usize> = (0..comp.len()).filter(|&i| comp.data[i] != 0).collect();
    let ztop = members
        .iter()
        .map(|&i| voxel_z(comp, i))
        .fold(f64::NEG_INFINITY, f64::max);
    *members
        .iter()
        .filter(|&&i| voxel_z(comp, i) > ztop - 3.0)
        .max_by(|&&x, &&y| dt_in[x].total_cmp(&dt_in[y]).then(y.cmp(&x)))
        .expect("the component is not empty")
}

/// What the sweep over geodesic shells found.
struct Sweep {
    /// Geodesic depth (mm) of each split where a branch was chosen.
    splits: Vec<f64>,
    /// The most central voxel 20 mm past the lobar split, when the followed branch gets there.
    target: Option<usize>,
    /// The followed voxels of the last shell that did not end the sweep.
    last_active: Vec<usize>,
}

/// Sweep the geodesic depth from `start` in shells, following one branch: a shell whose
/// followed voxels fall into two or more sizeable pieces (from 12 mm down) is a split, where
/// [`choose_branch`] keeps one piece and drops the others with everything below them.
fn sweep_shells(comp: &Volume<u8>, dt_in: &[f32], start: usize) -> Sweep {
    let (dims, sp, n) = (comp.dims, comp.spacing(), comp.len());
    let nb = neighbours(sp);
    let tree = dijkstra(&comp.data, dims, &nb, start, None, |_, _, l| l);
    let (geo, pred, order) = (&tree.dist, &tree.pred, &tree.order);
    // Label 1 = still followed, 2 = dropped; a voxel inherits its predecessor's label.
    let shell = (2.0f64).max(2.5 * sp[0].max(sp[1]).max(sp[2])) as f32;
    let mut label = vec![0u8; n];
    let mut slot = vec![u32::MAX; n];
    let mut sweep = Sweep {
        splits: Vec::new(),
        target: None,
        last_active: Vec::new(),
    };
    let mut idx = 0;
    while idx < order.len() {
        let s0 = (geo[order[idx] as usize] / shell).floor();
        let mut members = Vec::new();
        while idx < order.len() && (geo[order[idx] as usize] / shell).floor() == s0 {
            let v = order[idx] as usize;
            label[v] = if v == start {
                1
            } else {
                label[pred[v] as usize]
            };
            if label[v] == 1 {
                members.push(v);
            }
            idx += 1;
        }
        if members.is_empty() {
            break;
        }
        let comps = components(&members, dims, &nb, &mut slot);
        let largest = comps.iter().map(Vec::len).max().unwrap_or(0);
        let big: Vec<&Vec<usize>> = comps
            .iter()
            .filter(|c| c.len() >= 3 && c.len() * 8 >= largest)
            .collect();
        let depth = (s0 * shell) as f64;
        if big.len() >= 2 && depth >= 12.0 {
            let keep = choose_branch(&big, sweep.splits.len(), comp, dt_in);
            for &v in &members {
                label[v] = 2;
            }
            for &v in keep {
                label[v] = 1;
            }
            sweep.splits.push(depth);
            members = keep.clone();
        }
        if sweep.splits.len() >= 2 && depth >= sweep.splits[1] + 20.0 {
            sweep.target = best_of(&members, dt_in);
            break;
        }
        sweep.last_active = members;
    }
    sweep
}

/// The piece followed past split number `split` (0 = carina): the patient's left one (least
/// mean x), then the lower one (least mean z), then the thicker one (largest mean `dt_in`).
fn choose_branch<'p>(
    big: &[&'p Vec<usize>],
    split: usize,
    comp: &Volume<u8>,
    dt_in: &[f32],
) -> &'p Vec<usize> {
    let mean = |c: &Vec<usize>, f: &dyn Fn(usize) -> f64| {
        c.iter().map(|&v| f(v)).sum::<f64>() / c.len() as f64
    };
    let x = |v: usize| voxel_world(comp, v).x;
    let z = |v: usize| voxel_z(comp, v);
    let dt = |v: usize| dt_in[v] as f64;
    match split {
        0 => big
            .iter()
            .min_by(|p, q| mean(p, &x).total_cmp(&mean(q, &x))),
        1 => big
            .iter()
            .min_by(|p, q| mean(p, &z).total_cmp(&mean(q, &z))),
        _ => big
            .iter()
            .max_by(|p, q| mean(p, &dt).total_cmp(&mean(q, &dt))),
    }
    .copied()
    .expect("two or more pieces")
}

/// The most central voxel (largest distance to the wall) of a set.
fn best_of(set: &[usize], dt: &[f32]) -> Option<usize> {
    set.iter()
        .copied()
        .max_by(|&x, &y| dt[x].total_cmp(&dt[y]).then(y.cmp(&x)))
}

/// 26-connected pieces of `members` (union–find over a scratch slot map, restored after).
fn components(
    members: &[usize],
    dims: [usize; 3],
    nb: &[([i64; 3], f32)],
    slot: &mut [u32],
) -> Vec<Vec<usize>> {
    for (k, &v) in members.iter().enumerate() {
        slot[v] = k as u32;
    }
    let mut parent: Vec<usize> = (0..members.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for (k, &v) in members.iter().enumerate() {
        for (o, _) in nb {
            if let Some(u) = step(dims, v, o) {
                let j = slot[u];
                if j != u32::MAX {
                    let (a, b) = (find(&mut parent, k), find(&mut parent, j as usize));
                    if a != b {
                        parent[a.max(b)] = a.min(b);
                    }
                }
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut root_group = vec![usize::MAX; members.len()];
    for (k, &v) in members.iter().enumerate() {
        let r = find(&mut parent, k);
        if root_group[r] == usize::MAX {
            root_group[r] = groups.len();
            groups.push(Vec::new());
        }
        groups[root_group[r]].push(v);
    }
    for &v in members {
        slot[v] = u32::MAX;
    }
    groups
}
