//! Filling texels no frame saw: colours are pushed in from neighbours, wave by wave, first within
//! each chart (never across charts, so a chart's filler comes only from its own surface), then
//! into the gutter (so mip-mapping and filtering at chart borders never read black).

use crate::image::ImageError;

/// Fill the uncovered texels of an RGB atlas in place.
///
/// * `rgb`: `width * height * 3` linear RGB values, row-major; values of uncovered texels are
///   ignored and overwritten.
/// * `covered[i]`: texel `i` holds a measured colour.
/// * `chart_of_texel[i]`: chart id of texel `i`, `u32::MAX` for the gutter (see
///   [`super::TexelGeometry::chart_map`]).
///
/// Order: (1) each uncovered chart texel takes the mean of its already filled 8-neighbours of
/// the same chart, in breadth-first waves from the covered texels; (2) charts with no covered
/// texel at all take the mean of all covered colours (mid-grey if nothing is covered); (3) the
/// gutter is filled by the same waves from every chart texel. Afterwards no texel is unset.
///
/// Returns an error when the slice lengths do not match `width * height`.
pub fn fill_uncovered(
    rgb: &mut [f32],
    width: usize,
    height: usize,
    covered: &[bool],
    chart_of_texel: &[u32],
) -> crate::Result<()> {
    let n = width * height;
    if rgb.len() != 3 * n || covered.len() != n || chart_of_texel.len() != n {
        return Err(ImageError::BufferSize {
            stage: "atlas hole filling",
            what: "the atlas (RGB values / 3, coverage flags or chart ids)",
            got: (rgb.len() / 3).min(covered.len()).min(chart_of_texel.len()),
            expected: n,
        }
        .into());
    }
    let mut filled: Vec<bool> = covered.to_vec();
    // Stage 1: within charts.
    let same_chart = |a: usize, b: usize| chart_of_texel[a] == chart_of_texel[b];
    let seeds: Vec<usize> = (0..n).filter(|&i| filled[i]).collect();
    waves(
        rgb,
        width,
        height,
        &mut filled,
        seeds,
        &|i| chart_of_texel[i] != u32::MAX,
        &same_chart,
    );
    // Stage 2: charts nobody saw.
    let mut mean = [0.0f64; 3];
    let mut count = 0usize;
    for i in (0..n).filter(|&i| covered[i]) {
        for k in 0..3 {
            mean[k] += rgb[3 * i + k] as f64;
        }
        count += 1;
    }
    let mean = if count > 0 {
        mean.map(|m| (m / count as f64) as f32)
    } else {
        [0.5; 3]
    };
    for i in 0..n {
        if !filled[i] && chart_of_texel[i] != u32::MAX {
            rgb[3 * i..3 * i + 3].copy_from_slice(&mean);
            filled[i] = true;
        }
    }
    // Stage 3: the gutter, from every chart texel.
    let seeds: Vec<usize> = (0..n).filter(|&i| filled[i]).collect();
    waves(
        rgb,
        width,
        height,
        &mut filled,
        seeds,
        &|_| true,
        &|_, _| true,
    );
    // Only an atlas with no chart texel at all is left: make it the mean.
    for i in 0..n {
        if !filled[i] {
            rgb[3 * i..3 * i + 3].copy_from_slice(&mean);
        }
    }
    Ok(())
}

/// Breadth-first waves: every unfilled texel next to the current front (and allowed by
/// `target`) takes the mean of its filled neighbours that `linked` accepts.
fn waves(
    rgb: &mut [f32],
    w: usize,
    h: usize,
    filled: &mut [bool],
    mut front: Vec<usize>,
    target: &dyn Fn(usize) -> bool,
    linked: &dyn Fn(usize, usize) -> bool,
) {
    let mut queued = vec![false; w * h];
    let neighbours = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        let mut out = [usize::MAX; 8];
        let mut k = 0;
        for dy in -1..=1i64 {
            for dx in -1..=1i64 {
                let (nx, ny) = (x + dx, y + dy);
                if (dx != 0 || dy != 0) && nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64 {
                    out[k] = (ny as usize) * w + nx as usize;
                    k += 1;
                }
            }
        }
        out
    };
    while !front.is_empty() {
        let mut next = Vec::new();
        for &i in &front {
            for j in neighbours(i) {
                if j != usize::MAX && !filled[j] && !queued[j] && target(j) && linked(i, j) {
                    queued[j] = true;
                    next.push(j);
                }
            }
        }
        // Compute the whole wave from the previous state, then commit, so the result does not
        // depend on the visiting order.
        let values: Vec<[f32; 3]> = next
            .iter()
            .map(|&j| {
                let mut s = [0.0f32; 3];
                let mut c = 0.0f32;
                for k in neighbours(j) {
                    if k != usize::MAX && filled[k] && linked(j, k) {
                        for ch in 0..3 {
                            s[ch] += rgb[3 * k + ch];
                        }
                        c += 1.0;
                    }
                }
                s.map(|v| v / c.max(1.0))
            })
            .collect();
        for (&j, v) in next.iter().zip(&values) {
            rgb[3 * j..3 * j + 3].copy_from_slice(v);
            filled[j] = true;
        }
        front = next;
    }
}
