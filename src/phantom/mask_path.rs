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
    let dims = mask.dims;
    let sp = mask.spacing();
    let n = mask.len();
    let dt_in = inside_distance(mask);
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
    let comp = component_of(mask, seed);
    let dt_out: Vec<f32> = distance_transform_sq(dims, sp, |i| comp.data[i] != 0)
        .into_iter()
        .map(f32::sqrt)
        .collect();
    let half = ((sp[0] + sp[1] + sp[2]) / 6.0) as f32;
    let sdf_data: Vec<f32> = (0..n)
        .map(|i| {
            if comp.data[i] != 0 {
                half - dt_in[i]
            } else {
                dt_out[i] - half
            }
        })
        .collect();
    let sdf = Volume::from_data(dims, mask.affine, sdf_data)?;
    let a = mask.affine;
    let world = |i: usize| {
        mask.index_to_world(Point3::new(
            (i % dims[0]) as f64,
            ((i / dims[0]) % dims[1]) as f64,
            (i / (dims[0] * dims[1])) as f64,
        ))
    };
    let wz = |i: usize| {
        a[(2, 0)] * (i % dims[0]) as f64
            + a[(2, 1)] * ((i / dims[0]) % dims[1]) as f64
            + a[(2, 2)] * (i / (dims[0] * dims[1])) as f64
            + a[(2, 3)]
    };
    let members: Vec<usize> = (0..n).filter(|&i| comp.data[i] != 0).collect();
    let ztop = members
        .iter()
        .map(|&i| wz(i))
        .fold(f64::NEG_INFINITY, f64::max);
    let start = *members
        .iter()
        .filter(|&&i| wz(i) > ztop - 3.0)
        .max_by(|&&x, &&y| dt_in[x].total_cmp(&dt_in[y]).then(y.cmp(&x)))
        .expect("the component is not empty");
    let nb = neighbours(sp);
    let tree = dijkstra(&comp.data, dims, &nb, start, None, |_, _, l| l);
    let (geo, pred, order) = (&tree.dist, &tree.pred, &tree.order);

    // Sweep geodesic shells; label 1 = still followed, 2 = dropped.
    let shell = (2.0f64).max(2.5 * sp[0].max(sp[1]).max(sp[2])) as f32;
    let mut label = vec![0u8; n];
    let mut slot = vec![u32::MAX; n];
    let mut splits: Vec<f64> = Vec::new();
    let mut target: Option<usize> = None;
    let mut last_active: Vec<usize> = Vec::new();
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
        let big: Vec<&Vec<usize>> = {
            let largest = comps.iter().map(Vec::len).max().unwrap_or(0);
            comps
                .iter()
                .filter(|c| c.len() >= 3 && c.len() * 8 >= largest)
                .collect()
        };
        let depth = (s0 * shell) as f64;
        if big.len() >= 2 && depth >= 12.0 {
            let mean = |c: &Vec<usize>, f: &dyn Fn(usize) -> f64| {
                c.iter().map(|&v| f(v)).sum::<f64>() / c.len() as f64
            };
            let keep = match splits.len() {
                0 => big
                    .iter()
                    .min_by(|p, q| mean(p, &|v| world(v).x).total_cmp(&mean(q, &|v| world(v).x))),
                1 => big
                    .iter()
                    .min_by(|p, q| mean(p, &wz).total_cmp(&mean(q, &wz))),
                _ => big.iter().max_by(|p, q| {
                    mean(p, &|v| dt_in[v] as f64).total_cmp(&mean(q, &|v| dt_in[v] as f64))
                }),
            }
            .copied()
            .expect("two or more pieces");
            for &v in &members {
                label[v] = 2;
            }
            for &v in keep {
                label[v] = 1;
            }
            splits.push(depth);
            members = keep.clone();
        }
        if splits.len() >= 2 && depth >= splits[1] + 20.0 {
            target = best_of(&members, &dt_in);
            break;
        }
        last_active = members;
    }
    if splits.len() < 2 {
        return Err(GeometryError::Degenerate {
            stage: "mask centreline",
            message: format!(
                "found {} of the two expected splits (carina, lobar) below the top",
                splits.len()
            ),
        }
        .into());
    }
    let target = target
        .or_else(|| best_of(&last_active, &dt_in))
        .ok_or(VolumeError::Empty {
            stage: "mask centreline",
            what: "set of target voxels",
        })?;
    // Centred path: cost length / (dt + 0.5)², averaged over the edge's two voxels.
    let chain = centred_path(&comp, &dt_in, start, target)?;
    // The first 15 mm are dropped: segmentations often taper at the cut top of the trachea.
    let pts: Vec<Point3<f64>> = chain.into_iter().map(world).collect();
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
        split_depths_mm: splits,
    })
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
