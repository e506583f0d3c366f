//! 6-connected region growing: a scanline flood fill on the flat voxel array, and the
//! adaptive threshold with explosion control (Mori et al. 1996; Schlathoelter et al. 2002).

use super::error::VolumeError;
use super::Volume;
use crate::Result;

/// Scanline flood fill over 6-connected voxels for which `pass(index)` holds and `label` is 0.
///
/// Marks filled voxels with `tag`, starting from `seeds` (linear indices). Unlabelled voxels
/// that touch the region but fail `pass` are appended to `frontier` (possibly repeatedly), so a
/// later call with a looser predicate can resume from them. Stops early, returning
/// `(filled, true)`, once more than `limit` voxels were filled.
pub fn flood_fill(
    dims: [usize; 3],
    label: &mut [u8],
    seeds: &[u32],
    tag: u8,
    pass: impl Fn(usize) -> bool,
    mut frontier: Option<&mut Vec<u32>>,
    limit: usize,
) -> (usize, bool) {
    let [nx, ny, nz] = dims;
    let slice = nx * ny;
    let mut stack: Vec<u32> = seeds.to_vec();
    let mut filled = 0usize;
    while let Some(idx) = stack.pop() {
        let idx = idx as usize;
        if label[idx] != 0 {
            continue;
        }
        if !pass(idx) {
            if let Some(f) = frontier.as_deref_mut() {
                f.push(idx as u32);
            }
            continue;
        }
        let x = idx % nx;
        let row = idx - x;
        let (mut l, mut r) = (x, x);
        while l > 0 && label[row + l - 1] == 0 && pass(row + l - 1) {
            l -= 1;
        }
        while r + 1 < nx && label[row + r + 1] == 0 && pass(row + r + 1) {
            r += 1;
        }
        label[row + l..=row + r].fill(tag);
        filled += r - l + 1;
        if let Some(f) = frontier.as_deref_mut() {
            if l > 0 && label[row + l - 1] == 0 {
                f.push((row + l - 1) as u32);
            }
            if r + 1 < nx && label[row + r + 1] == 0 {
                f.push((row + r + 1) as u32);
            }
        }
        let y = (row / nx) % ny;
        let z = row / slice;
        let neighbours = [
            (y > 0).then(|| row - nx),
            (y + 1 < ny).then(|| row + nx),
            (z > 0).then(|| row - slice),
            (z + 1 < nz).then(|| row + slice),
        ];
        for nrow in neighbours.into_iter().flatten() {
            let mut in_run = false;
            #[allow(clippy::needless_range_loop)] // `pass` takes the linear index
            for n in nrow + l..=nrow + r {
                if label[n] == 0 {
                    if pass(n) {
                        if !in_run {
                            stack.push(n as u32);
                            in_run = true;
                        }
                        continue;
                    } else if let Some(f) = frontier.as_deref_mut() {
                        f.push(n as u32);
                    }
                }
                in_run = false;
            }
        }
        if filled > limit {
            return (filled, true);
        }
    }
    (filled, false)
}

/// Voxels 6-connected to `seed` with `lower <= value <= upper` (both inclusive, as SimpleITK's
/// ConnectedThreshold). Returns a 0/1 mask on the volume's grid.
pub fn connected_threshold(
    vol: &Volume<f32>,
    seed: [usize; 3],
    lower: f32,
    upper: f32,
) -> Result<Volume<u8>> {
    check_seed(vol, seed)?;
    let mut label = vec![0u8; vol.len()];
    let d = &vol.data;
    flood_fill(
        vol.dims,
        &mut label,
        &[vol.index(seed[0], seed[1], seed[2]) as u32],
        1,
        |i| d[i] >= lower && d[i] <= upper,
        None,
        usize::MAX,
    );
    Volume::from_data(vol.dims, vol.affine, label)
}

fn check_seed(vol: &Volume<f32>, seed: [usize; 3]) -> Result<()> {
    if (0..3).any(|a| seed[a] >= vol.dims[a]) {
        return Err(VolumeError::SeedOutsideGrid {
            seed,
            dims: vol.dims,
        }
        .into());
    }
    if vol.len() >= u32::MAX as usize {
        return Err(VolumeError::GridTooLarge {
            stage: "region growing",
            dims: vol.dims,
        }
        .into());
    }
    Ok(())
}

/// The adaptive threshold's schedule and its explosion-control rule.
#[derive(Clone, Debug)]
pub struct AdaptiveOptions {
    /// First upper threshold tried (HU).
    pub start_hu: f32,
    /// Increase of the threshold per step (HU).
    pub step_hu: f32,
    /// Highest threshold tried (HU).
    pub max_hu: f32,
    /// Explosion: a step whose volume exceeds this factor times the previous step's volume.
    pub leak_growth_limit: f64,
    /// Explosion: a step whose volume exceeds this many ml (airways hold ~20–200 ml).
    pub max_volume_ml: f64,
}

impl Default for AdaptiveOptions {
    fn default() -> Self {
        AdaptiveOptions {
            start_hu: -950.0,
            step_hu: 25.0,
            max_hu: -500.0,
            leak_growth_limit: 2.0,
            max_volume_ml: 600.0,
        }
    }
}

/// One threshold tried by [`grow_adaptive`].
#[derive(Clone, Debug, PartialEq)]
pub struct ThresholdStep {
    /// Upper threshold (HU).
    pub hu: f32,
    /// Region size at this threshold (voxels); for the exploding step, the size when stopped.
    pub voxels: usize,
}

/// Result of [`grow_adaptive`].
#[derive(Clone, Debug)]
pub struct AdaptiveGrowth {
    /// 0/1 region at the chosen threshold.
    pub mask: Volume<u8>,
    /// Thresholds tried in order, the last one possibly the explosion.
    pub steps: Vec<ThresholdStep>,
    /// Index into `steps` of the chosen (last good) threshold.
    pub chosen: usize,
    /// True when the schedule ended on an explosion rather than at `max_hu`.
    pub exploded: bool,
}

/// Grow from `seed` below a rising threshold and keep the last threshold before the region
/// explodes into the parenchyma.
///
/// Each step resumes from the previous region's rejected neighbours, so the whole schedule
/// costs about one flood fill; a step is abandoned as soon as it passes the growth limit.
pub fn grow_adaptive(
    vol: &Volume<f32>,
    seed: [usize; 3],
    opts: &AdaptiveOptions,
) -> Result<AdaptiveGrowth> {
    check_seed(vol, seed)?;
    // Written negated so NaN options are rejected too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let bad =
        !(opts.step_hu > 0.0) || !(opts.max_hu >= opts.start_hu) || !(opts.leak_growth_limit > 1.0);
    if bad {
        return Err(VolumeError::BadThresholds {
            start_hu: opts.start_hu,
            max_hu: opts.max_hu,
            step_hu: opts.step_hu,
            leak_growth_limit: opts.leak_growth_limit,
        }
        .into());
    }
    let n_steps = ((opts.max_hu - opts.start_hu) / opts.step_hu).floor() as usize + 1;
    if n_steps > 254 {
        return Err(VolumeError::TooManySteps { steps: n_steps }.into());
    }
    let sp = vol.spacing();
    let voxel_ml = sp[0] * sp[1] * sp[2] / 1000.0;
    let max_voxels = (opts.max_volume_ml / voxel_ml) as usize;
    let d = &vol.data;
    let mut label = vec![0u8; vol.len()];
    let mut pending = vec![vol.index(seed[0], seed[1], seed[2]) as u32];
    let mut steps = Vec::new();
    let mut total = 0usize;
    let mut exploded = false;
    for s in 0..n_steps {
        let thr = opts.start_hu + s as f32 * opts.step_hu;
        let limit = if total > 0 {
            ((total as f64 * opts.leak_growth_limit) as usize).min(max_voxels)
        } else {
            max_voxels
        };
        let mut frontier = Vec::new();
        let budget = limit.saturating_sub(total);
        let (added, stopped) = flood_fill(
            vol.dims,
            &mut label,
            &pending,
            s as u8 + 1,
            |i| d[i] <= thr,
            Some(&mut frontier),
            budget,
        );
        steps.push(ThresholdStep {
            hu: thr,
            voxels: total + added,
        });
        if stopped {
            exploded = true;
            break;
        }
        total += added;
        pending = frontier;
    }
    let chosen = if exploded {
        steps.len().saturating_sub(2)
    } else {
        steps.len() - 1
    };
    if exploded && steps.len() < 2 {
        return Err(VolumeError::ExplodedAtStart {
            start_hu: opts.start_hu,
            seed,
        }
        .into());
    }
    if steps[chosen].voxels == 0 {
        return Err(VolumeError::SeedNotAir {
            seed,
            value: vol.get(seed[0], seed[1], seed[2]),
            max_hu: steps[chosen].hu,
        }
        .into());
    }
    let keep = chosen as u8 + 1;
    for v in label.iter_mut() {
        *v = u8::from(*v != 0 && *v <= keep);
    }
    Ok(AdaptiveGrowth {
        mask: Volume::from_data(vol.dims, vol.affine, label)?,
        steps,
        chosen,
        exploded,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;

    /// Breadth-first 6-connected fill: the obvious reference for the scanline version.
    fn bfs(vol: &Volume<f32>, seed: [usize; 3], upper: f32) -> Vec<u8> {
        let [nx, ny, nz] = vol.dims;
        let mut m = vec![0u8; vol.len()];
        let mut q = std::collections::VecDeque::new();
        if vol.get(seed[0], seed[1], seed[2]) <= upper {
            m[vol.index(seed[0], seed[1], seed[2])] = 1;
            q.push_back(seed);
        }
        while let Some([x, y, z]) = q.pop_front() {
            let cand = [
                (x > 0).then(|| [x - 1, y, z]),
                (x + 1 < nx).then(|| [x + 1, y, z]),
                (y > 0).then(|| [x, y - 1, z]),
                (y + 1 < ny).then(|| [x, y + 1, z]),
                (z > 0).then(|| [x, y, z - 1]),
                (z + 1 < nz).then(|| [x, y, z + 1]),
            ];
            for c in cand.into_iter().flatten() {
                let i = vol.index(c[0], c[1], c[2]);
                if m[i] == 0 && vol.data[i] <= upper {
                    m[i] = 1;
                    q.push_back(c);
                }
            }
        }
        m
    }

    #[test]
    fn scanline_fill_equals_breadth_first_fill_on_random_volumes() {
        let mut r = crate::rng::Pcg32::new(3, 3);
        for t in 0..20 {
            let dims = [17 + t, 13, 11];
            let data: Vec<f32> = (0..dims[0] * dims[1] * dims[2])
                .map(|_| r.uniform() as f32)
                .collect();
            let vol = Volume::from_data(dims, Affine::identity(), data).unwrap();
            let seed = [t % dims[0], 6, 5];
            let upper = 0.55 + 0.01 * t as f32;
            let ours = connected_threshold(&vol, seed, f32::MIN, upper).unwrap();
            let want = bfs(&vol, seed, upper);
            assert_eq!(ours.data, want, "case {t}");
        }
    }

    #[test]
    fn adaptive_threshold_stops_before_the_leak() {
        // A tube of -1000 in a -850 background, its wall +40 except a -700 gap at one voxel:
        // thresholds up to -725 keep the tube; -700 leaks into the background and must be refused.
        let dims = [40, 40, 40];
        let mut v = Volume::filled(dims, Affine::identity(), -850.0f32);
        for z in 0..40 {
            for y in 15..26 {
                for x in 15..26 {
                    let r2 = (x as i32 - 20).pow(2) + (y as i32 - 20).pow(2);
                    let val = if r2 <= 9 {
                        -1000.0
                    } else if r2 <= 25 {
                        40.0
                    } else {
                        continue;
                    };
                    v.set(x, y, z, val);
                }
            }
        }
        v.set(24, 20, 20, -700.0);
        v.set(25, 20, 20, -700.0);
        let g = grow_adaptive(&v, [20, 20, 5], &AdaptiveOptions::default()).unwrap();
        assert!(g.exploded);
        assert_eq!(g.steps[g.chosen].hu, -725.0);
        let tube = v.data.iter().filter(|&&x| x == -1000.0).count();
        assert_eq!(g.mask.data.iter().filter(|&&m| m == 1).count(), tube);
    }
}
