//! Count airway branches in a segmentation from geodesic distance shells.
//!
//! Method: geodesic distance (26-connected, steps weighted by their world length) inside the
//! mask from its top-most axial slice (the trachea's cut end); voxels are grouped into shells
//! of `shell_mm`; each shell's 26-connected components become nodes of a tree whose parent is
//! the touching component one shell closer. A node whose subtree reaches at least
//! `min_branch_mm` further is "significant"; every node with k >= 2 significant children is a
//! bifurcation that starts k branches. Branches = roots + sum of those k. Short bumps (noise
//! on the wall) never reach `min_branch_mm` and are not counted.

use super::Volume;
use crate::math::Vector3;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Shell width and the shortest branch counted (mm).
#[derive(Clone, Debug)]
pub struct BranchCountOptions {
    /// Width of a geodesic distance shell (mm).
    pub shell_mm: f64,
    /// A side branch counts when it reaches this far beyond its bifurcation (mm).
    pub min_branch_mm: f64,
}

impl Default for BranchCountOptions {
    fn default() -> Self {
        BranchCountOptions {
            shell_mm: 1.0,
            min_branch_mm: 2.0,
        }
    }
}

/// Geodesic distance (mm) inside `mask` from its top-most axial slice; `f32::INFINITY`
/// outside the mask or where unreachable.
pub fn geodesic_from_top(mask: &Volume<u8>) -> Vec<f32> {
    let [nx, ny, nz] = mask.dims;
    let col = |a: usize| {
        Vector3::new(
            mask.affine[(0, a)],
            mask.affine[(1, a)],
            mask.affine[(2, a)],
        )
    };
    let ax = (0..3)
        .max_by(|&a, &b| col(a).z.abs().total_cmp(&col(b).z.abs()))
        .unwrap_or(2);
    let up = col(ax).z > 0.0;
    let coord = |n: usize| [n % nx, (n / nx) % ny, n / (nx * ny)];
    let mut dist = vec![f32::INFINITY; mask.len()];
    let mut heap = BinaryHeap::new();
    // Top-most slice holding mask voxels.
    let top = mask
        .data
        .iter()
        .enumerate()
        .filter(|(_, &m)| m != 0)
        .map(|(n, _)| coord(n)[ax])
        .reduce(|a, b| if up { a.max(b) } else { a.min(b) });
    let Some(top) = top else { return dist };
    for (n, &m) in mask.data.iter().enumerate() {
        if m != 0 && coord(n)[ax] == top {
            dist[n] = 0.0;
            heap.push(Reverse((0u32, n as u32)));
        }
    }
    let sp = mask.spacing();
    let mut offs = Vec::new();
    for dk in -1i64..=1 {
        for dj in -1i64..=1 {
            for di in -1i64..=1 {
                if (di, dj, dk) != (0, 0, 0) {
                    let w = ((di as f64 * sp[0]).powi(2)
                        + (dj as f64 * sp[1]).powi(2)
                        + (dk as f64 * sp[2]).powi(2))
                    .sqrt();
                    offs.push((di, dj, dk, w as f32));
                }
            }
        }
    }
    while let Some(Reverse((bits, n))) = heap.pop() {
        let d = f32::from_bits(bits);
        let n = n as usize;
        if d > dist[n] {
            continue;
        }
        let [i, j, k] = coord(n);
        for &(di, dj, dk, w) in &offs {
            let (a, b, c) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
            if a < 0 || b < 0 || c < 0 || a >= nx as i64 || b >= ny as i64 || c >= nz as i64 {
                continue;
            }
            let m = a as usize + nx * (b as usize + ny * c as usize);
            if mask.data[m] == 0 {
                continue;
            }
            let nd = d + w;
            if nd < dist[m] {
                dist[m] = nd;
                // Non-negative f32 bit patterns order like their values.
                heap.push(Reverse((nd.to_bits(), m as u32)));
            }
        }
    }
    dist
}

/// Number of airway branches in `mask` (see the module documentation for the method).
pub fn count_branches(mask: &Volume<u8>, opts: &BranchCountOptions) -> usize {
    let [nx, ny, nz] = mask.dims;
    let dist = geodesic_from_top(mask);
    // Shells thinner than a voxel break into fragments: never go below the largest spacing.
    let shell_mm = opts
        .shell_mm
        .max(mask.spacing().into_iter().fold(0.0, f64::max));
    let shell: Vec<u32> = dist
        .iter()
        .map(|&d| {
            if d.is_finite() {
                (d as f64 / shell_mm) as u32
            } else {
                u32::MAX
            }
        })
        .collect();
    let mut comp = vec![u32::MAX; mask.len()];
    let mut comp_shell: Vec<u32> = Vec::new();
    let mut parent: Vec<Option<u32>> = Vec::new();
    let neighbours = |n: usize, out: &mut Vec<usize>| {
        out.clear();
        let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
        for c in k.saturating_sub(1)..=(k + 1).min(nz - 1) {
            for b in j.saturating_sub(1)..=(j + 1).min(ny - 1) {
                for a in i.saturating_sub(1)..=(i + 1).min(nx - 1) {
                    let m = a + nx * (b + ny * c);
                    if m != n {
                        out.push(m);
                    }
                }
            }
        }
    };
    let mut nb = Vec::with_capacity(26);
    let mut stack = Vec::new();
    // Label shell components in order of distance so parents exist before children.
    let mut order: Vec<usize> = (0..mask.len()).filter(|&n| shell[n] != u32::MAX).collect();
    order.sort_unstable_by_key(|&n| shell[n]);
    for &start in &order {
        if comp[start] != u32::MAX {
            continue;
        }
        let id = comp_shell.len() as u32;
        let s = shell[start];
        comp_shell.push(s);
        let mut par = None;
        comp[start] = id;
        stack.push(start);
        while let Some(n) = stack.pop() {
            neighbours(n, &mut nb);
            for &m in &nb {
                if shell[m] == s && comp[m] == u32::MAX {
                    comp[m] = id;
                    stack.push(m);
                } else if par.is_none() && s > 0 && shell[m] == s - 1 && comp[m] != u32::MAX {
                    par = Some(comp[m]);
                }
            }
        }
        parent.push(par);
    }
    let nc = comp_shell.len();
    // Height (in shells) of each component's subtree, children before parents.
    let mut height = vec![1u32; nc];
    for c in (0..nc).rev() {
        if let Some(p) = parent[c] {
            let h = height[c] + 1;
            if h > height[p as usize] {
                height[p as usize] = h;
            }
        }
    }
    let min_shells = (opts.min_branch_mm / shell_mm).ceil() as u32;
    let mut significant_children = vec![0usize; nc];
    let mut roots = 0;
    for c in 0..nc {
        match parent[c] {
            Some(p) if height[c] >= min_shells => significant_children[p as usize] += 1,
            None if comp_shell[c] == 0 => roots += 1,
            _ => {}
        }
    }
    roots
        + significant_children
            .iter()
            .filter(|&&k| k >= 2)
            .sum::<usize>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;

    #[test]
    fn a_y_shaped_tube_has_three_branches() {
        // A vertical stem that splits into two diverging arms, 1 mm voxels.
        let dims = [40, 12, 40];
        let mut m = Volume::filled(dims, Affine::identity(), 0u8);
        for k in 0..40usize {
            for j in 3..9 {
                for i in 0..40usize {
                    let zc = 39 - k as i64; // distance from the top
                    let inside = if zc < 15 {
                        (i as i64 - 20).abs() <= 3
                    } else {
                        let off = zc - 15;
                        (i as i64 - 20 - off).abs() <= 3 || (i as i64 - 20 + off).abs() <= 3
                    };
                    if inside {
                        m.set(i, j, k, 1);
                    }
                }
            }
        }
        assert_eq!(count_branches(&m, &BranchCountOptions::default()), 3);
    }
}
