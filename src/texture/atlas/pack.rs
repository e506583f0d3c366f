//! Chart packing: rotate each chart to its minimum-area bounding rectangle, rasterise its texel
//! footprint (every texel a bilinear lookup inside the chart can touch, grown by half the gutter)
//! and place the footprints with a raster packer, so irregular charts nest.

use rayon::prelude::*;

use super::raster::{point_in_triangle, square_hits_triangle};

/// Bilinear support radius (texels) plus a margin for the rounding of packed UVs: footprints are
/// a superset of what [`super::rasterize_texels`] later assigns to the chart.
const SUPPORT: f64 = 1.0 + 1e-2;

/// A chart ready for packing, in texel units.
pub(crate) struct Footprint {
    /// UV of each chart vertex relative to the footprint's corner (texels).
    pub uv: Vec<[f64; 2]>,
    /// Footprint size (texels).
    pub w: usize,
    pub h: usize,
    /// Occupied texels, row-major `w * h` (chart texels grown by half the gutter).
    pub mask: Vec<bool>,
    /// Texels within bilinear reach of the chart.
    pub chart_texels: usize,
    /// Texels whose centre lies inside one of the chart's triangles.
    pub inner_texels: usize,
}

/// Where a footprint went: corner (texels) and how it was turned.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Placement {
    pub x: usize,
    pub y: usize,
    /// Quarter turns counter-clockwise (0..4).
    pub rot: u8,
}

/// Turn `uv` (texels) to its minimum-area bounding rectangle, wider than tall, and rasterise it.
pub(crate) fn footprint(uv: &[[f64; 2]], tris: &[[u32; 3]], grow: usize) -> Footprint {
    let mut uv = min_area_rotation(uv);
    let (mut lo, mut hi) = bounds(&uv);
    if hi[1] - lo[1] > hi[0] - lo[0] {
        for p in &mut uv {
            *p = [-p[1], p[0]];
        }
        (lo, hi) = bounds(&uv);
    }
    // A margin that holds the bilinear reach and the growth, then cropped to what is occupied.
    let m = (grow + 2) as f64;
    for p in &mut uv {
        p[0] += m - lo[0].floor();
        p[1] += m - lo[1].floor();
    }
    let w = (hi[0] - lo[0].floor() + 2.0 * m).ceil() as usize + 1;
    let h = (hi[1] - lo[1].floor() + 2.0 * m).ceil() as usize + 1;
    let mut core = vec![false; w * h];
    let mut inner = vec![false; w * h];
    for t in tris {
        let [a, b, c] = t.map(|v| uv[v as usize]);
        let x0 = (a[0].min(b[0]).min(c[0]) - SUPPORT - 0.5).floor().max(0.0) as usize;
        let y0 = (a[1].min(b[1]).min(c[1]) - SUPPORT - 0.5).floor().max(0.0) as usize;
        let x1 = ((a[0].max(b[0]).max(c[0]) + SUPPORT - 0.5).ceil() as usize).min(w - 1);
        let y1 = ((a[1].max(b[1]).max(c[1]) + SUPPORT - 0.5).ceil() as usize).min(h - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let ctr = [x as f64 + 0.5, y as f64 + 0.5];
                if square_hits_triangle(ctr, SUPPORT, a, b, c) {
                    core[y * w + x] = true;
                    if point_in_triangle(ctr, a, b, c) {
                        inner[y * w + x] = true;
                    }
                }
            }
        }
    }
    let chart_texels = core.iter().filter(|&&b| b).count();
    let inner_texels = inner.iter().filter(|&&b| b).count();
    let mask = dilate(&core, w, h, grow);
    // Crop to the occupied rectangle.
    let (mut cx0, mut cy0, mut cx1, mut cy1) = (w, h, 0, 0);
    for y in 0..h {
        for x in 0..w {
            if mask[y * w + x] {
                cx0 = cx0.min(x);
                cy0 = cy0.min(y);
                cx1 = cx1.max(x);
                cy1 = cy1.max(y);
            }
        }
    }
    if cx0 > cx1 {
        // No area at all (cannot happen for a triangle with finite UVs); keep one texel.
        (cx0, cy0, cx1, cy1) = (0, 0, 0, 0);
    }
    let (nw, nh) = (cx1 - cx0 + 1, cy1 - cy0 + 1);
    let mut cropped = vec![false; nw * nh];
    for y in 0..nh {
        cropped[y * nw..(y + 1) * nw]
            .copy_from_slice(&mask[(y + cy0) * w + cx0..(y + cy0) * w + cx0 + nw]);
    }
    for p in &mut uv {
        p[0] -= cx0 as f64;
        p[1] -= cy0 as f64;
    }
    Footprint {
        uv,
        w: nw,
        h: nh,
        mask: cropped,
        chart_texels,
        inner_texels,
    }
}

fn bounds(uv: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in uv {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Box dilation by `r` texels (separable: rows then columns).
fn dilate(m: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    if r == 0 {
        return m.to_vec();
    }
    let mut rows = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            if m[y * w + x] {
                for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                    rows[y * w + xx] = true;
                }
            }
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            if rows[y * w + x] {
                for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                    out[yy * w + x] = true;
                }
            }
        }
    }
    out
}

/// Rotate `uv` so that its bounding rectangle has minimum area (one hull edge on an axis).
fn min_area_rotation(uv: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let hull = convex_hull(uv);
    let mut best = (f64::INFINITY, 1.0, 0.0);
    for i in 0..hull.len() {
        let (p, q) = (hull[i], hull[(i + 1) % hull.len()]);
        let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
        let l = (dx * dx + dy * dy).sqrt();
        if l == 0.0 {
            continue;
        }
        let (c, s) = (dx / l, dy / l);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for h in &hull {
            let r = [c * h[0] + s * h[1], -s * h[0] + c * h[1]];
            for k in 0..2 {
                lo[k] = lo[k].min(r[k]);
                hi[k] = hi[k].max(r[k]);
            }
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if area < best.0 {
            best = (area, c, s);
        }
    }
    let (_, c, s) = best;
    uv.iter()
        .map(|p| [c * p[0] + s * p[1], -s * p[0] + c * p[1]])
        .collect()
}

/// Andrew's monotone chain; counter-clockwise, without collinear points.
fn convex_hull(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = h.len();
        let it: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in it {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

/// Texel (x, y) of a footprint after turning it by `rot` quarter turns counter-clockwise.
fn turn(f: &Footprint, rot: u8, x: usize, y: usize) -> (usize, usize) {
    match rot & 3 {
        0 => (x, y),
        1 => (f.h - 1 - y, x),
        2 => (f.w - 1 - x, f.h - 1 - y),
        _ => (y, f.w - 1 - x),
    }
}

/// A turned footprint as one occupied span per row: (row, first column, one past the last).
/// Filling each row's span is conservative and lets the fit test skip whole runs of texels.
struct Spans {
    rows: Vec<(usize, usize, usize)>,
    w: usize,
    h: usize,
}

fn spans(f: &Footprint, rot: u8) -> Spans {
    let (w, h) = if rot & 1 == 1 { (f.h, f.w) } else { (f.w, f.h) };
    let mut lo = vec![usize::MAX; h];
    let mut hi = vec![0usize; h];
    for y in 0..f.h {
        for x in 0..f.w {
            if f.mask[y * f.w + x] {
                let (c, r) = turn(f, rot, x, y);
                lo[r] = lo[r].min(c);
                hi[r] = hi[r].max(c + 1);
            }
        }
    }
    let rows = (0..h)
        .filter(|&r| lo[r] < hi[r])
        .map(|r| (r, lo[r], hi[r]))
        .collect();
    Spans { rows, w, h }
}

/// Atlas occupancy, one bit per texel, rows allocated as the atlas grows.
struct Occupancy {
    width: usize,
    words: usize,
    rows: Vec<Vec<u64>>,
}

impl Occupancy {
    fn new(width: usize) -> Self {
        Occupancy {
            width,
            words: width.div_ceil(64),
            rows: Vec::new(),
        }
    }

    /// Smallest s >= start with texels [s, s + len) of row y free and s + len <= width.
    fn free_run(&self, y: usize, start: usize, len: usize) -> Option<usize> {
        let Some(row) = self.rows.get(y) else {
            return (start + len <= self.width).then_some(start);
        };
        let bit = |i: usize| row[i / 64] >> (i % 64) & 1 == 1;
        let mut s = start;
        while s + len <= self.width {
            // Skip occupied texels word by word.
            while s < self.width && bit(s) {
                let ones = (!(row[s / 64] >> (s % 64))).trailing_zeros() as usize;
                s += ones.max(1);
            }
            if s + len > self.width {
                return None;
            }
            // Length of the free run from s.
            let mut e = s;
            while e < s + len {
                let word = row[e / 64] >> (e % 64);
                let zeros = (word.trailing_zeros() as usize).min(64 - e % 64);
                if zeros == 0 {
                    break;
                }
                e += zeros;
            }
            if e >= s + len {
                return Some(s);
            }
            s = e;
        }
        None
    }

    /// Leftmost x at which `sp` fits with its top-left at row y.
    fn fit_at(&self, sp: &Spans, y: usize) -> Option<usize> {
        let mut x = 0usize;
        'retry: loop {
            if x + sp.w > self.width {
                return None;
            }
            for &(r, lo, hi) in &sp.rows {
                let s = self.free_run(y + r, x + lo, hi - lo)?;
                if s > x + lo {
                    x = s - lo;
                    continue 'retry;
                }
            }
            return Some(x);
        }
    }

    fn set(&mut self, x: usize, y: usize) {
        while self.rows.len() <= y {
            self.rows.push(vec![0; self.words]);
        }
        self.rows[y][x / 64] |= 1 << (x % 64);
    }
}

/// Pack footprints into an atlas `width` texels wide, largest first, each at the lowest then
/// leftmost position (over four quarter turns) where it overlaps nothing: a raster
/// ("tetris") packer, so irregular charts nest into each other's gaps. Returns placements and
/// the atlas height.
pub(crate) fn raster_pack(fps: &[Footprint], width: usize) -> Option<(Vec<Placement>, usize)> {
    let mut order: Vec<usize> = (0..fps.len()).collect();
    let area: Vec<usize> = fps
        .iter()
        .map(|f| f.mask.iter().filter(|&&b| b).count())
        .collect();
    order.sort_by(|&a, &b| area[b].cmp(&area[a]).then(a.cmp(&b)));
    let turned: Vec<[Spans; 4]> = fps
        .par_iter()
        .map(|f| [0, 1, 2, 3].map(|r| spans(f, r)))
        .collect();
    let mut occ = Occupancy::new(width);
    let mut out = vec![Placement { x: 0, y: 0, rot: 0 }; fps.len()];
    for i in order {
        // Lowest top edge over the turns, then lowest row, then leftmost.
        let mut best: Option<(usize, usize, usize, u8)> = None;
        for rot in 0..4u8 {
            let sp = &turned[i][rot as usize];
            if sp.w > width {
                continue;
            }
            let limit = best.map_or(usize::MAX, |b| b.0);
            let mut y = 0;
            while y + sp.h < limit {
                if let Some(x) = occ.fit_at(sp, y) {
                    let cand = (y + sp.h, y, x, rot);
                    if best.is_none_or(|b| cand < b) {
                        best = Some(cand);
                    }
                    break;
                }
                y += 1;
            }
        }
        let (_, y, x, rot) = best?;
        let f = &fps[i];
        for fy in 0..f.h {
            for fx in 0..f.w {
                if f.mask[fy * f.w + fx] {
                    let (c, r) = turn(f, rot, fx, fy);
                    occ.set(x + c, y + r);
                }
            }
        }
        out[i] = Placement { x, y, rot };
    }
    Some((out, occ.rows.len().max(1)))
}

/// The UV (texels, atlas frame) of a footprint vertex after placement.
pub(crate) fn place_uv(f: &Footprint, p: &Placement, uv: [f64; 2]) -> [f64; 2] {
    let (w, h) = (f.w as f64, f.h as f64);
    let [u, v] = match p.rot & 3 {
        0 => uv,
        1 => [h - uv[1], uv[0]],
        2 => [w - uv[0], h - uv[1]],
        _ => [uv[1], w - uv[0]],
    };
    [u + p.x as f64, v + p.y as f64]
}
