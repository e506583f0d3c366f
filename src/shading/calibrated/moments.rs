//! Sufficient statistics of the calibrated fit, per frame, and the cost, gradient and
//! Gauss–Newton matrix computed from them.
//!
//! For frame f and channel c the model is `y_fc · psi` with the feature vector
//! `psi = (alb_c B(gamma) ⊗ B(t) / z^2, 1)` (D + 1 values, D = (n_rho + 1)(n_s + 1)) and the
//! coefficients `y_fc = (g_f vec(rho_c s^T), a_fc)`. So the weighted cost of a frame is exactly
//! `y^T G y - 2 h^T y + s` with `G = sum w psi psi^T`, `h = sum w P psi`, `s = sum w P^2`:
//! one pass over the samples, after which every alternation step and every Levenberg–Marquardt
//! iteration costs microseconds per frame regardless of the sample count.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::samples::PooledSamples;
use super::specular::lobe;
use crate::shading::bernstein::basis_into;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Sizes of the bases.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Layout {
    /// Coefficients of rho per channel (degree + 1).
    pub nr: usize,
    /// Coefficients of s (degree + 1), the first fixed to 1.
    pub ns: usize,
    /// Frames.
    pub frames: usize,
    /// Whether the ambient term a_fc is a parameter.
    pub ambient: bool,
    /// Whether the inter-reflection term `kappa_c L_f` is in the model (kappa_c: 3
    /// parameters; L_f: the frame's mean observed luminance, [`FrameMoments::light`]).
    pub interreflection: bool,
    /// Whether the gathered inter-reflection is in the model: a second feature
    /// `alb_c E_c` per sample (E: [`PooledSamples::indirect`]) with coefficient `g_f k_c`
    /// (k_c: 3 parameters after kappa).
    pub gathered: bool,
    /// The specular lobe's GGX alpha when the model has the specular term: features
    /// `spec(gamma) B(t) / z^2` (not multiplied by the albedo) with coefficients `g_f k_c s`
    /// (k_c: the last parameters).
    pub specular: Option<f64>,
    /// Parameters of the specular colour: 1 (one k for every channel: a white light) or 3.
    pub spec_colours: usize,
}

impl Layout {
    /// Length of the shading part of the feature vector.
    pub fn d(&self) -> usize {
        self.nr * self.ns
    }
    /// Offset of channel c's rho coefficients in the parameter vector.
    pub fn c_off(&self, c: usize) -> usize {
        c * self.nr
    }
    /// Offset of s_1..s_m.
    pub fn e_off(&self) -> usize {
        3 * self.nr
    }
    /// Offset of the gains.
    pub fn g_off(&self) -> usize {
        3 * self.nr + self.ns - 1
    }
    /// Offset of the ambient terms (3 per frame).
    pub fn a_off(&self) -> usize {
        self.g_off() + self.frames
    }
    /// Offset of kappa (3 values, one per channel).
    pub fn k_off(&self) -> usize {
        self.a_off() + if self.ambient { 3 * self.frames } else { 0 }
    }
    /// Offset of the gathered light's factor k (3 values, one per channel).
    pub fn q_off(&self) -> usize {
        self.k_off() + if self.interreflection { 3 } else { 0 }
    }
    /// Offset of the specular colour k (3 values, one per channel).
    pub fn p_off(&self) -> usize {
        self.q_off() + if self.gathered { 3 } else { 0 }
    }
    /// Features after the shading ones: 1 (the light that does not depend on the surface),
    /// the gathered light when in the model, then the specular ones (`ns`).
    pub fn extra(&self) -> usize {
        1 + usize::from(self.gathered) + if self.specular.is_some() { self.ns } else { 0 }
    }
    /// Index of the first specular feature.
    pub fn spec_feature(&self) -> usize {
        self.d() + 1 + usize::from(self.gathered)
    }
    /// Length of the parameter vector.
    pub fn len(&self) -> usize {
        self.p_off()
            + if self.specular.is_some() {
                self.spec_colours
            } else {
                0
            }
    }
    /// Index of channel c's specular colour k_c (one index for every channel when white).
    pub fn k_idx(&self, c: usize) -> usize {
        self.p_off() + c.min(self.spec_colours.max(1) - 1)
    }
}

/// One frame's moments. `g` holds one matrix shared by the channels, or one per channel when
/// a per-sample albedo enters the features.
#[derive(Debug, Clone)]
pub(crate) struct FrameMoments {
    pub g: Vec<DMatrix<f64>>,
    pub h: [DVector<f64>; 3],
    pub s: [f64; 3],
    /// The frame's mean observed luminance over its surface pixels (0 when not pooled).
    pub light: f64,
}

impl FrameMoments {
    pub fn g(&self, c: usize) -> &DMatrix<f64> {
        &self.g[c.min(self.g.len() - 1)]
    }
}

/// Per-sample precomputation: t of every sample (the angle coordinate).
pub(crate) fn t_of(samples: &PooledSamples, cos_edge: f64) -> Vec<f32> {
    let span = (1.0 - cos_edge).max(1e-12);
    samples
        .cos_theta
        .iter()
        .map(|&c| ((1.0 - f64::from(c)) / span).clamp(0.0, 1.0) as f32)
        .collect()
}

/// The shading features `B(gamma) ⊗ B(t) / z^2` of sample i into `phi` (length D).
#[inline]
pub(crate) fn features(
    lay: &Layout,
    gamma: f64,
    t: f64,
    z: f64,
    bg: &mut [f64],
    bt: &mut [f64],
    phi: &mut [f64],
) {
    basis_into(gamma, bg);
    basis_into(t, bt);
    let inv = 1.0 / (z * z);
    for j in 0..lay.nr {
        let a = bg[j] * inv;
        for k in 0..lay.ns {
            phi[j * lay.ns + k] = a * bt[k];
        }
    }
}

/// One pass per frame (parallel over frames): the moments with sample weights `w`
/// (0 skips a sample) and, if given, the per-sample albedo per channel.
pub(crate) fn accumulate(
    samples: &PooledSamples,
    t: &[f32],
    w: &[f32],
    albedo: Option<&[Vec<f32>; 3]>,
    lay: &Layout,
) -> Vec<FrameMoments> {
    let d = lay.d();
    let d1 = d + lay.extra();
    let sp = lay.spec_feature();
    let nmat = if albedo.is_some() || lay.gathered {
        3
    } else {
        1
    };
    let indirect = samples.indirect.as_ref().filter(|_| lay.gathered);
    (0..samples.frames())
        .into_par_iter()
        .map(|f| {
            let mut g = vec![vec![0.0f64; d1 * d1]; nmat];
            let mut h = [vec![0.0f64; d1], vec![0.0; d1], vec![0.0; d1]];
            let mut s = [0.0f64; 3];
            let (mut bg, mut bt) = (vec![0.0; lay.nr], vec![0.0; lay.ns]);
            let mut psi = vec![0.0f64; d1];
            let mut psic = vec![0.0f64; d1];
            psi[d] = 1.0;
            let mut q = 0.0;
            for i in samples.frame_start[f]..samples.frame_start[f + 1] {
                let wi = f64::from(w[i]);
                if wi == 0.0 {
                    continue;
                }
                let (gam, z) = (f64::from(samples.gamma[i]), f64::from(samples.z[i]));
                features(
                    lay,
                    gam,
                    f64::from(t[i]),
                    z,
                    &mut bg,
                    &mut bt,
                    &mut psi[..d],
                );
                if let Some(alpha) = lay.specular {
                    let l = lobe(alpha, gam) / (z * z);
                    for k in 0..lay.ns {
                        psi[sp + k] = l * bt[k];
                    }
                }
                for c in 0..3 {
                    let p = f64::from(samples.rgb[c][i]);
                    s[c] += wi * p * p;
                    // Albedo scales the shading features only (the ambient light is not reflected
                    // off this texel alone).
                    let alb = albedo.map_or(1.0, |a| f64::from(a[c][i]));
                    // The last features: 1 (the light that does not depend on the surface),
                    // and the gathered light reflected by this texel.
                    if let Some(e) = indirect {
                        q = alb * f64::from(e[c][i]);
                    }
                    let hc = &mut h[c];
                    for k in 0..d {
                        hc[k] += wi * p * alb * psi[k];
                    }
                    hc[d] += wi * p;
                    if lay.gathered {
                        hc[d + 1] += wi * p * q;
                    }
                    for k in sp..d1 {
                        hc[k] += wi * p * psi[k];
                    }
                    if c < nmat {
                        for k in 0..d {
                            psic[k] = alb * psi[k];
                        }
                        psic[d] = 1.0;
                        if lay.gathered {
                            psic[d + 1] = q;
                        }
                        psic[sp..].copy_from_slice(&psi[sp..]);
                        let gm = &mut g[c];
                        for j in 0..d1 {
                            let a = wi * psic[j];
                            let row = &mut gm[j * d1..(j + 1) * d1];
                            for (x, &q) in row[j..].iter_mut().zip(&psic[j..]) {
                                *x += a * q;
                            }
                        }
                    }
                }
            }
            let g = g
                .into_iter()
                .map(|m| {
                    DMatrix::from_fn(
                        d1,
                        d1,
                        |r, c| if r <= c { m[r * d1 + c] } else { m[c * d1 + r] },
                    )
                })
                .collect();
            FrameMoments {
                g,
                h: h.map(DVector::from_vec),
                s,
                light: samples.frame_light.get(f).copied().unwrap_or(0.0),
            }
        })
        .collect()
}

/// The light of frame f, channel c that does not depend on the surface's orientation or
/// distance: `a_fc` and/or `kappa_c L_f` (`light` = L_f).
pub(crate) fn ambient_of(lay: &Layout, p: &[f64], light: f64, f: usize, c: usize) -> f64 {
    let mut a = 0.0;
    if lay.ambient {
        a += p[lay.a_off() + 3 * f + c];
    }
    if lay.interreflection {
        a += p[lay.k_off() + c] * light;
    }
    a
}

/// The coefficient `g_f k_c` of the gathered light of frame f, channel c.
pub(crate) fn gathered_of(lay: &Layout, p: &[f64], f: usize, c: usize) -> f64 {
    p[lay.g_off() + f] * p[lay.q_off() + c]
}

/// The coefficient vector `y_fc = (g_f vec(rho_c s^T), ambient_fc, [g_f k_c gathered],
/// [g_f k_c s])` from the parameters.
pub(crate) fn y_of(lay: &Layout, p: &[f64], light: f64, f: usize, c: usize) -> DVector<f64> {
    let mut y = DVector::zeros(lay.d() + lay.extra());
    y_into(lay, p, light, f, c, y.as_mut_slice());
    y
}

/// [`y_of`] into `y` (length D + extra).
fn y_into(lay: &Layout, p: &[f64], light: f64, f: usize, c: usize, y: &mut [f64]) {
    y.fill(0.0);
    let d = lay.d();
    let gf = p[lay.g_off() + f];
    let rho = &p[lay.c_off(c)..lay.c_off(c) + lay.nr];
    for j in 0..lay.nr {
        for k in 0..lay.ns {
            let e = if k == 0 { 1.0 } else { p[lay.e_off() + k - 1] };
            y[j * lay.ns + k] = gf * rho[j] * e;
        }
    }
    y[d] = ambient_of(lay, p, light, f, c);
    if lay.gathered {
        y[d + 1] = gathered_of(lay, p, f, c);
    }
    if lay.specular.is_some() {
        let kc = gf * p[lay.k_idx(c)];
        let sp = lay.spec_feature();
        for k in 0..lay.ns {
            let e = if k == 0 { 1.0 } else { p[lay.e_off() + k - 1] };
            y[sp + k] = kc * e;
        }
    }
}

/// The weighted cost `sum_fc y^T G y - 2 h^T y + s` at parameters `p`.
pub(crate) fn cost(lay: &Layout, m: &[FrameMoments], p: &[f64]) -> f64 {
    let mut total = 0.0;
    for (f, fm) in m.iter().enumerate() {
        for c in 0..3 {
            let y = y_of(lay, p, fm.light, f, c);
            let gy = fm.g(c) * &y;
            total += y.dot(&gy) - 2.0 * fm.h[c].dot(&y) + fm.s[c];
        }
    }
    total.max(0.0)
}

/// The parameters a solver step updates: [`normal_equations`] forms only their rows and
/// columns of `H` and their entries of the gradient, which is all a block step reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Block {
    /// Every parameter (the Levenberg–Marquardt polish).
    All,
    /// rho of every channel.
    Rho,
    /// s_1.. (s_0 is fixed to 1).
    S,
    /// The gains and, when in the model, the ambient terms.
    Gains,
    /// kappa.
    Kappa,
    /// The gathered light's factor k.
    Gathered,
    /// The specular colour k.
    Specular,
}

impl Block {
    /// Which columns of a frame and channel's local Jacobian (in [`local_indices`]' order)
    /// the block holds.
    fn local_columns(self, lay: &Layout) -> Vec<bool> {
        let cols = LocalColumns::of(lay);
        (0..local_len(lay))
            .map(|col| match self {
                Block::All => true,
                Block::Rho => col < lay.nr,
                Block::S => (lay.nr..cols.g).contains(&col),
                Block::Gains => col == cols.g || (lay.ambient && col == cols.g + 1),
                Block::Kappa => lay.interreflection && col == cols.kappa,
                Block::Gathered => lay.gathered && col == cols.q,
                Block::Specular => lay.specular.is_some() && col == cols.k,
            })
            .collect()
    }
}

/// Where a frame and channel's local Jacobian holds the parameters after rho and s: the gain
/// (the ambient term follows it when in the model), kappa, the gathered light's k and the
/// specular colour's k; a column the model lacks holds the next one's index.
struct LocalColumns {
    g: usize,
    kappa: usize,
    q: usize,
    k: usize,
}

impl LocalColumns {
    fn of(lay: &Layout) -> Self {
        let g = lay.nr + lay.ns - 1;
        let kappa = g + 1 + usize::from(lay.ambient);
        let q = kappa + usize::from(lay.interreflection);
        let k = q + usize::from(lay.gathered);
        LocalColumns { g, kappa, q, k }
    }
}

/// Gauss–Newton matrix `H = sum J^T G J` and half-gradient `J^T (G y - h)` over all
/// parameters (dense; a few hundred parameters at most), and the cost. Only `block`'s rows and
/// columns of `H` and entries of the gradient are formed (the rest are 0); each is the same to
/// the bit as with [`Block::All`]. The frames' shares are computed in parallel into one buffer
/// and added in frame order, so the result does not depend on the threads.
pub(crate) fn normal_equations(
    lay: &Layout,
    m: &[FrameMoments],
    p: &[f64],
    block: Block,
) -> (DMatrix<f64>, DVector<f64>, f64) {
    let np = lay.len();
    let n = local_len(lay);
    let want = block.local_columns(lay);
    let wanted: Vec<usize> = (0..n).filter(|&b| want[b]).collect();
    let d1 = lay.d() + lay.extra();
    // Per frame: 3 channels' blocks of J^T G J (n x n each), of J^T (G y - h) and costs.
    let mut hl = vec![0.0; m.len() * 3 * n * n];
    let mut gl = vec![0.0; m.len() * 3 * n];
    let mut costs = vec![0.0; m.len() * 3];
    hl.par_chunks_mut(3 * n * n)
        .zip(gl.par_chunks_mut(3 * n))
        .zip(costs.par_chunks_mut(3))
        .enumerate()
        .for_each_init(
            || LocalScratch::new(d1, n),
            |scratch, (f, ((hl, gl), costs))| {
                for c in 0..3 {
                    costs[c] = local_terms(
                        lay,
                        &m[f],
                        p,
                        f,
                        c,
                        (&want, &wanted),
                        scratch,
                        &mut hl[c * n * n..(c + 1) * n * n],
                        &mut gl[c * n..(c + 1) * n],
                    );
                }
            },
        );
    let mut hm = DMatrix::zeros(np, np);
    let mut grad = DVector::zeros(np);
    let mut total = 0.0;
    let mut idx = Vec::with_capacity(n);
    for f in 0..m.len() {
        for c in 0..3 {
            let k = 3 * f + c;
            total += costs[k];
            local_indices(lay, f, c, &mut idx);
            let (hl, gl) = (&hl[k * n * n..(k + 1) * n * n], &gl[k * n..(k + 1) * n]);
            for &a in &wanted {
                grad[idx[a]] += gl[a];
                for &b in &wanted {
                    hm[(idx[a], idx[b])] += hl[a * n + b];
                }
            }
        }
    }
    (hm, grad, total.max(0.0))
}

/// Parameters one frame and channel's coefficients depend on.
fn local_len(lay: &Layout) -> usize {
    lay.nr
        + lay.ns
        + usize::from(lay.ambient)
        + usize::from(lay.interreflection)
        + usize::from(lay.gathered)
        + usize::from(lay.specular.is_some())
}

/// Frame f, channel c's parameters, in the order of its local Jacobian's columns: rho_c (nr),
/// s_1.. (ns - 1), g_f, then the optional ones.
fn local_indices(lay: &Layout, f: usize, c: usize, idx: &mut Vec<usize>) {
    idx.clear();
    idx.extend((0..lay.nr).map(|j| lay.c_off(c) + j));
    idx.extend((1..lay.ns).map(|k| lay.e_off() + k - 1));
    idx.push(lay.g_off() + f);
    if lay.ambient {
        idx.push(lay.a_off() + 3 * f + c);
    }
    if lay.interreflection {
        idx.push(lay.k_off() + c);
    }
    if lay.gathered {
        idx.push(lay.q_off() + c);
    }
    if lay.specular.is_some() {
        idx.push(lay.k_idx(c));
    }
}

/// Buffers one thread reuses for every frame's [`local_terms`]: the normal equations are
/// formed thousands of times per fit, each from 3 x frames small blocks.
struct LocalScratch {
    y: DVector<f64>,
    gy: DVector<f64>,
    jac: Vec<(usize, usize, f64)>,
    gj: Vec<f64>,
}

impl LocalScratch {
    fn new(d1: usize, n: usize) -> Self {
        LocalScratch {
            y: DVector::zeros(d1),
            gy: DVector::zeros(d1),
            jac: Vec::new(),
            gj: vec![0.0; d1 * n],
        }
    }
}

/// Frame f, channel c's share of the normal equations: its block of `J^T G J` into `hl`
/// (row-major, over [`local_indices`]) and of `J^T (G y - h)` into `gl`, the rows and columns
/// `wanted` only (`want[col]`: whether column col is among them; the others are left 0);
/// returns its cost.
#[allow(clippy::too_many_arguments)]
fn local_terms(
    lay: &Layout,
    fm: &FrameMoments,
    p: &[f64],
    f: usize,
    c: usize,
    (want, wanted): (&[bool], &[usize]),
    scratch: &mut LocalScratch,
    hl: &mut [f64],
    gl: &mut [f64],
) -> f64 {
    let d = lay.d();
    let d1 = d + lay.extra();
    let gf = p[lay.g_off() + f];
    let LocalScratch { y, gy, jac, gj } = scratch;
    y_into(lay, p, fm.light, f, c, y.as_mut_slice());
    let gm = fm.g(c);
    gm.mul_to(y, gy);
    let cost = y.dot(gy) - 2.0 * fm.h[c].dot(y) + fm.s[c];
    // The residual G y - h, in place of G y.
    for (r, h) in gy.iter_mut().zip(fm.h[c].iter()) {
        *r -= h;
    }
    let r = &*gy;
    // Local Jacobian dy/dparams, columns in [`local_indices`]' order. It is sparse (each
    // coefficient of y depends on a few parameters), so it is kept as (row, column, value)
    // entries.
    let LocalColumns {
        g: col_g,
        kappa: col_kappa,
        q: col_q,
        k: col_k,
    } = LocalColumns::of(lay);
    jac.clear();
    let rho = &p[lay.c_off(c)..lay.c_off(c) + lay.nr];
    for j in 0..lay.nr {
        for k in 0..lay.ns {
            let e = if k == 0 { 1.0 } else { p[lay.e_off() + k - 1] };
            let row = j * lay.ns + k;
            jac.push((row, j, gf * e));
            if k > 0 {
                jac.push((row, lay.nr + k - 1, gf * rho[j]));
            }
            jac.push((row, col_g, rho[j] * e));
        }
    }
    if lay.ambient {
        jac.push((d, lay.nr + lay.ns, 1.0));
    }
    if lay.interreflection {
        jac.push((d, col_kappa, fm.light));
    }
    if lay.gathered {
        jac.push((d + 1, col_g, p[lay.q_off() + c]));
        jac.push((d + 1, col_q, gf));
    }
    if lay.specular.is_some() {
        let kc = p[lay.k_idx(c)];
        let sp = lay.spec_feature();
        for k in 0..lay.ns {
            let e = if k == 0 { 1.0 } else { p[lay.e_off() + k - 1] };
            jac.push((sp + k, col_k, gf * e));
            jac.push((sp + k, col_g, kc * e));
            if k > 0 {
                jac.push((sp + k, lay.nr + k - 1, gf * kc));
            }
        }
    }
    let n = gl.len();
    // G J (d1 x n, column-major), the wanted columns. G is symmetric, so its column `row`
    // (contiguous in nalgebra's column-major storage) is its row `row`.
    gj.fill(0.0);
    let g_all = gm.as_slice();
    for &(row, col, v) in jac.iter().filter(|e| want[e.1]) {
        let g_col = &g_all[row * d1..(row + 1) * d1];
        for (out, &g) in gj[col * d1..(col + 1) * d1].iter_mut().zip(g_col) {
            *out += g * v;
        }
    }
    hl.fill(0.0);
    gl.fill(0.0);
    for &(row, col, v) in jac.iter().filter(|e| want[e.1]) {
        gl[col] += v * r[row];
        for &b in wanted {
            hl[col * n + b] += v * gj[b * d1 + row];
        }
    }
    cost
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The sparse local Jacobians against a numerical one of `y_of`, every optional term on:
    /// `H = sum J^T G J` and `J^T (G y - h)`, and the cost against `cost`.
    #[test]
    fn normal_equations_match_a_numerical_jacobian() {
        let lay = Layout {
            nr: 3,
            ns: 3,
            frames: 4,
            ambient: true,
            interreflection: true,
            gathered: true,
            specular: Some(0.3),
            spec_colours: 1,
        };
        let mut rng = SplitMix64::new(7);
        let d1 = lay.d() + lay.extra();
        let m: Vec<FrameMoments> = (0..lay.frames)
            .map(|_| {
                let g = (0..3)
                    .map(|_| {
                        let a = DMatrix::from_fn(d1, d1, |_, _| rng.uniform() - 0.5);
                        &a * a.transpose()
                    })
                    .collect();
                FrameMoments {
                    g,
                    h: std::array::from_fn(|_| DVector::from_fn(d1, |_, _| rng.uniform())),
                    s: [10.0, 11.0, 12.0],
                    light: 0.4 + rng.uniform(),
                }
            })
            .collect();
        let p: Vec<f64> = (0..lay.len()).map(|_| 0.2 + rng.uniform()).collect();
        let (h, grad, total) = normal_equations(&lay, &m, &p, Block::All);
        let np = lay.len();
        let mut h_ref = DMatrix::<f64>::zeros(np, np);
        let mut g_ref = DVector::<f64>::zeros(np);
        for (f, fm) in m.iter().enumerate() {
            for c in 0..3 {
                let y = y_of(&lay, &p, fm.light, f, c);
                let jac = DMatrix::from_fn(d1, np, |r, k| {
                    let (mut hi, mut lo) = (p.clone(), p.clone());
                    hi[k] += 1e-6;
                    lo[k] -= 1e-6;
                    (y_of(&lay, &hi, fm.light, f, c)[r] - y_of(&lay, &lo, fm.light, f, c)[r]) / 2e-6
                });
                h_ref += jac.transpose() * fm.g(c) * &jac;
                g_ref += jac.transpose() * (fm.g(c) * &y - &fm.h[c]);
            }
        }
        let scale = h_ref.amax();
        assert!((&h - &h_ref).amax() < 1e-6 * scale, "H differs");
        assert!(
            (&grad - &g_ref).amax() < 1e-6 * g_ref.amax(),
            "gradient differs"
        );
        assert!((total - cost(&lay, &m, &p)).abs() < 1e-9 * total.abs().max(1.0));

        // Each block's rows and columns, and only those, the same to the bit as in the whole.
        let blocks = [
            (Block::Rho, (0..lay.e_off()).collect::<Vec<_>>()),
            (Block::S, (lay.e_off()..lay.g_off()).collect()),
            (Block::Gains, (lay.g_off()..lay.k_off()).collect()),
            (Block::Kappa, (lay.k_off()..lay.q_off()).collect()),
            (Block::Gathered, (lay.q_off()..lay.p_off()).collect()),
            (Block::Specular, (lay.p_off()..lay.len()).collect()),
        ];
        for (block, params) in blocks {
            let (hb, gb, tb) = normal_equations(&lay, &m, &p, block);
            assert_eq!(tb.to_bits(), total.to_bits());
            for i in 0..np {
                let in_i = params.contains(&i);
                let expected = if in_i { grad[i] } else { 0.0 };
                assert_eq!(
                    gb[i].to_bits(),
                    expected.to_bits(),
                    "{block:?} gradient {i}"
                );
                for j in 0..np {
                    let expected = if in_i && params.contains(&j) {
                        h[(i, j)]
                    } else {
                        0.0
                    };
                    assert_eq!(
                        hb[(i, j)].to_bits(),
                        expected.to_bits(),
                        "{block:?} H {i} {j}"
                    );
                }
            }
        }
    }
}
