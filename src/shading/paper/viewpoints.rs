//! Which fitted viewpoints shade a new view, and with which weights.
//!
//! The paper takes the Psi of the nearest fitted viewpoint (by camera centre). While flying,
//! the nearest viewpoint switches abruptly and so does the shading. The blended mode weighs the
//! k nearest viewpoints (unstructured-lumigraph style, Buehler et al. 2001): with penalty
//! `p_i = |c_i - c| + direction_mm · (1 - v_i·v)` and `p_k+1` the (k+1)-th smallest penalty,
//! `w_i ∝ (1 - p_i / p_k+1) / p_i`. A viewpoint's weight reaches 0 exactly when it leaves the
//! k nearest, so the shading changes continuously along any camera path.

use super::psi::PsiModel;
use crate::camera::pose::{camera_centre, viewing_direction};
use crate::math::{Affine, Point3, Vector3};

/// How the fitted viewpoints' Psi are chosen for a new view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PsiLookup {
    /// The paper: the viewpoint with the nearest camera centre (ties by viewing direction).
    Nearest,
    /// Blend the `k` nearest viewpoints with continuous weights.
    KNearest {
        /// Number of viewpoints blended (at least 1).
        k: usize,
    },
}

/// The lookups by name (the command line's `render --shading`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PsiLookupKind {
    /// The Psi of the nearest fitted viewpoint (the paper).
    Nearest,
    /// The k nearest viewpoints' Psi blended continuously.
    Blend,
}

impl PsiLookup {
    /// Viewpoints blended by default.
    pub const DEFAULT_K: usize = 4;

    /// The lookup `kind`; `k` (at least 1) viewpoints are blended by [`PsiLookupKind::Blend`].
    pub fn of_kind(kind: PsiLookupKind, k: usize) -> PsiLookup {
        match kind {
            PsiLookupKind::Nearest => PsiLookup::Nearest,
            PsiLookupKind::Blend => PsiLookup::KNearest { k: k.max(1) },
        }
    }
}

impl std::fmt::Display for PsiLookup {
    /// "nearest" or "k-nearest (k = 4)".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PsiLookup::Nearest => write!(f, "nearest"),
            PsiLookup::KNearest { k } => write!(f, "k-nearest (k = {k})"),
        }
    }
}

impl Default for PsiLookup {
    fn default() -> Self {
        PsiLookup::KNearest {
            k: PsiLookup::DEFAULT_K,
        }
    }
}

/// Camera centres (world mm) and viewing directions of the fitted viewpoints.
#[derive(Clone, Debug)]
pub struct ViewpointIndex {
    centres: Vec<Point3<f64>>,
    dirs: Vec<Vector3<f64>>,
    /// Weight of the viewing direction in the blend penalty: mm per unit of `1 - cos(angle)`.
    pub direction_mm: f64,
}

/// Distances closer than this (mm) count as ties in the nearest-viewpoint rule.
const TIE_MM: f64 = 1e-9;

impl ViewpointIndex {
    /// Index the viewpoints of `psi` (their `camera_to_world`, row-major).
    pub fn new(psi: &[PsiModel]) -> ViewpointIndex {
        let poses: Vec<Affine> = psi
            .iter()
            .map(|p| Affine::from_row_slice(&p.camera_to_world))
            .collect();
        ViewpointIndex::from_poses(&poses)
    }

    /// Index camera → world poses.
    pub fn from_poses(poses: &[Affine]) -> ViewpointIndex {
        let (centres, dirs) = poses
            .iter()
            .map(|m| (camera_centre(m), viewing_direction(m)))
            .unzip();
        ViewpointIndex {
            centres,
            dirs,
            direction_mm: 5.0,
        }
    }

    /// Number of viewpoints.
    pub fn len(&self) -> usize {
        self.centres.len()
    }

    /// True when there is no viewpoint.
    pub fn is_empty(&self) -> bool {
        self.centres.is_empty()
    }

    /// The paper's rule: index of the nearest camera centre; among centres equally near, the
    /// one whose viewing direction is closest to the new one. `None` without viewpoints.
    pub fn nearest(&self, camera_to_world: &Affine) -> Option<usize> {
        let c = camera_centre(camera_to_world);
        let v = viewing_direction(camera_to_world);
        let mut best: Option<(usize, f64, f64)> = None;
        for (i, (ci, vi)) in self.centres.iter().zip(&self.dirs).enumerate() {
            let d = (ci - c).norm();
            let cos = vi.dot(&v);
            best = match best {
                Some((_, bd, bc)) if d > bd + TIE_MM || (d > bd - TIE_MM && cos <= bc) => best,
                _ => Some((i, d, cos)),
            };
        }
        best.map(|b| b.0)
    }

    /// Viewpoints and normalised weights (summing to 1) for a new camera.
    pub fn weights(&self, camera_to_world: &Affine, mode: PsiLookup) -> Vec<(usize, f64)> {
        match mode {
            PsiLookup::Nearest => self.nearest(camera_to_world).map(|i| vec![(i, 1.0)]),
            PsiLookup::KNearest { k } => Some(self.blend(camera_to_world, k.max(1))),
        }
        .unwrap_or_default()
    }

    fn blend(&self, camera_to_world: &Affine, k: usize) -> Vec<(usize, f64)> {
        let c = camera_centre(camera_to_world);
        let v = viewing_direction(camera_to_world);
        let mut pen: Vec<(usize, f64)> = self
            .centres
            .iter()
            .zip(&self.dirs)
            .enumerate()
            .map(|(i, (ci, vi))| {
                let p = (ci - c).norm() + self.direction_mm * (1.0 - vi.dot(&v)).max(0.0);
                (i, p)
            })
            .collect();
        pen.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        if pen.is_empty() {
            return pen;
        }
        // An exact match takes all the weight (the fitted Psi of that very viewpoint).
        if pen[0].1 <= TIE_MM {
            return vec![(pen[0].0, 1.0)];
        }
        let thresh = if pen.len() > k {
            pen[k].1
        } else {
            // Fewer than k + 1 viewpoints: let the farthest still count.
            pen[pen.len() - 1].1 * 1.5
        };
        pen.truncate(k);
        let mut out: Vec<(usize, f64)> = pen
            .into_iter()
            .map(|(i, p)| (i, ((1.0 - p / thresh).max(0.0)) / p))
            .filter(|(_, w)| *w > 0.0)
            .collect();
        let sum: f64 = out.iter().map(|x| x.1).sum();
        if sum <= 0.0 {
            // All k share the (k+1)-th penalty: equal weights.
            let n = k.min(self.len());
            return (0..n).map(|j| (j, 1.0 / n as f64)).collect::<Vec<_>>();
        }
        for x in &mut out {
            x.1 /= sum;
        }
        out
    }
}

/// Per-view shading: Psi models with weights, evaluated with gamma and z of the new view (the
/// light moves with the camera).
#[derive(Clone, Debug)]
pub struct BlendedPsi<'a> {
    terms: Vec<(&'a PsiModel, f32)>,
}

impl<'a> BlendedPsi<'a> {
    /// Shading of a new camera from the fitted models.
    pub fn new(
        psi: &'a [PsiModel],
        index: &ViewpointIndex,
        camera_to_world: &Affine,
        mode: PsiLookup,
    ) -> BlendedPsi<'a> {
        let terms = index
            .weights(camera_to_world, mode)
            .into_iter()
            .map(|(i, w)| (&psi[i], w as f32))
            .collect();
        BlendedPsi { terms }
    }

    /// The viewpoints used and their weights.
    pub fn terms(&self) -> impl Iterator<Item = (&'a PsiModel, f32)> + '_ {
        self.terms.iter().copied()
    }

    /// Weighted sum of `Psi_i(gamma, z)` for R, G, B (linear intensity); z in mm.
    #[inline]
    pub fn eval_rgb(&self, gamma: f32, z: f32) -> [f32; 3] {
        let mut out = [0.0f32; 3];
        for (m, w) in &self.terms {
            let p = m.eval_rgb(gamma as f64, z as f64);
            for k in 0..3 {
                out[k] += w * p[k] as f32;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::ExclusionCounts;

    fn at(x: f64, dir_z: f64) -> PsiModel {
        // Rotation about y so the viewing direction (third column) is (sin, 0, cos).
        let s = (1.0 - dir_z * dir_z).sqrt();
        PsiModel {
            camera_to_world: [
                dir_z, 0.0, s, x, 0.0, 1.0, 0.0, 0.0, -s, 0.0, dir_z, 0.0, 0.0, 0.0, 0.0, 1.0,
            ],
            z_min: 1.0,
            z_max: 10.0,
            c: [[x; 4]; 3],
            d: [[1.0; 3]; 3],
            rms_residual: [0.0; 3],
            samples_used: 0,
            excluded: ExclusionCounts::default(),
        }
    }

    fn pose(x: f64) -> Affine {
        let mut m = Affine::identity();
        m[(0, 3)] = x;
        m
    }

    #[test]
    fn nearest_by_centre_then_direction() {
        let psi = vec![at(0.0, 1.0), at(2.0, 0.8), at(2.0, 1.0), at(10.0, 1.0)];
        let idx = ViewpointIndex::new(&psi);
        assert_eq!(idx.nearest(&pose(0.9)), Some(0));
        // Centres 1 and 2 coincide: 2 looks along the new camera's +z.
        assert_eq!(idx.nearest(&pose(1.9)), Some(2));
        assert_eq!(idx.nearest(&pose(7.0)), Some(3));
    }

    #[test]
    fn blend_weights_are_normalised_and_continuous() {
        let psi: Vec<PsiModel> = (0..6).map(|i| at(i as f64 * 3.0, 1.0)).collect();
        let idx = ViewpointIndex::new(&psi);
        let mode = PsiLookup::KNearest { k: 3 };
        let mut prev: Option<f32> = None;
        for s in 0..=300 {
            let x = s as f64 * 0.05;
            let w = idx.weights(&pose(x), mode);
            let sum: f64 = w.iter().map(|t| t.1).sum();
            assert!((sum - 1.0).abs() < 1e-12);
            assert!(w.len() <= 3);
            // Shading rho(1) = c_3 = x of each viewpoint: blended value moves continuously.
            let b = BlendedPsi::new(&psi, &idx, &pose(x), mode).eval_rgb(1.0, 1.0)[0];
            if let Some(p) = prev {
                assert!((b - p).abs() < 0.35, "jump {p} -> {b} at x = {x}");
            }
            prev = Some(b);
        }
        // An exact match gets all the weight.
        assert_eq!(idx.weights(&pose(6.0), mode), vec![(2, 1.0)]);
    }
}
