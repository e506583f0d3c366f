//! The correction a video's frames agree on. A tracker's error is a drift shared by
//! neighbouring frames, so where most frames of a round registered to scattered poses (each
//! to its own local minimum, from poses several millimetres off) the median of the
//! corrections of a frame's neighbours is still close to its own error: on ATM_224 from
//! 4 mm / 5 deg, single frames ended 0.4-6 mm and 1-65 deg off (22 of 30 outliers), and the
//! median over each frame's seven nearest brought every frame to 1.3 mm / 3.1 deg, from which
//! the round converged on 28 of 30 (BENCHMARKS.md, session 27).

use super::pose::{apply_delta, delta_between, PoseDelta};
use crate::math::Affine;

/// The given poses corrected by the median correction of each frame's `2 half_window + 1`
/// nearest usable frames (itself included when usable): `measured[f]` is where frame `f`
/// registered from `given[f]`, `usable[f]` whether that registration reached a cost at all
/// (an outlier is usable: the median is there to outvote it). Medians are taken per
/// component of the world-frame shift and rotation vector. `None` when fewer than three
/// frames are usable.
pub fn consensus_poses(
    given: &[Affine],
    measured: &[Affine],
    usable: &[bool],
    half_window: usize,
) -> Option<Vec<Affine>> {
    let corrections: Vec<[f64; 6]> = given
        .iter()
        .zip(measured)
        .map(|(g, m)| delta_between(g, m).to_array())
        .collect();
    let good: Vec<usize> = (0..given.len()).filter(|&f| usable[f]).collect();
    if good.len() < 3 {
        return None;
    }
    let take = (2 * half_window + 1).min(good.len());
    let poses = (0..given.len())
        .map(|f| {
            let mut near = good.clone();
            near.sort_by_key(|&k| (k.abs_diff(f), k));
            near.truncate(take);
            let median: [f64; 6] = std::array::from_fn(|c| {
                let mut v: Vec<f64> = near.iter().map(|&k| corrections[k][c]).collect();
                v.sort_by(f64::total_cmp);
                let mid = v.len() / 2;
                match v.len() % 2 {
                    1 => v[mid],
                    _ => 0.5 * (v[mid - 1] + v[mid]),
                }
            });
            apply_delta(&given[f], &PoseDelta::from_array(&median))
        })
        .collect();
    Some(poses)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::pose::{perturb, pose_error};

    /// A camera flying along +z, frame `f` 1 mm further, turning slowly.
    fn path(n: usize) -> Vec<Affine> {
        (0..n)
            .map(|f| {
                let base = Affine::new_translation(&crate::math::Vector3::new(0.0, 0.0, f as f64));
                perturb(&base, &[0.0, 0.0, 0.0, 0.0, 0.01 * f as f64, 0.0])
            })
            .collect()
    }

    #[test]
    fn scattered_registrations_agree_on_the_shared_error() {
        let truth = path(30);
        // The tracker's error: one drift for the whole run (2 mm, 3 deg).
        let error = PoseDelta::from_array(&[1.2, -1.6, 0.3, 0.03, -0.04, 0.02]);
        let given: Vec<Affine> = truth.iter().map(|t| apply_delta(t, &error)).collect();
        // Most frames register near the truth with scatter; every third ends far off.
        let measured: Vec<Affine> = truth
            .iter()
            .enumerate()
            .map(|(f, t)| {
                let s = ((f * 7919) % 13) as f64 / 13.0 - 0.5;
                match f % 3 {
                    0 => perturb(t, &[3.0 * s + 2.0, -2.5, 1.0, 0.3 * s, 0.2, -0.4]),
                    _ => perturb(
                        t,
                        &[0.4 * s, -0.3 * s, 0.2 * s, 0.005 * s, -0.004 * s, 0.003 * s],
                    ),
                }
            })
            .collect();
        let mut usable = vec![true; 30];
        usable[10] = false; // e.g. too few points: kept at its given pose
        let agreed = consensus_poses(&given, &truth_or(&measured, &given, &usable), &usable, 3)
            .expect("enough usable frames");
        for (f, (a, t)) in agreed.iter().zip(&truth).enumerate() {
            let (mm, deg) = pose_error(a, t);
            let (gm, gd) = pose_error(&given[f], t);
            assert!(
                gm > 2.0 && gd > 2.9,
                "frame {f} given {gm:.2} mm {gd:.2} deg"
            );
            assert!(mm < 0.4 && deg < 0.3, "frame {f}: {mm:.2} mm {deg:.2} deg");
        }
    }

    /// The measured poses, with frames that are not usable left at their given poses (as a
    /// registration that could not compare them leaves them).
    fn truth_or(measured: &[Affine], given: &[Affine], usable: &[bool]) -> Vec<Affine> {
        (0..measured.len())
            .map(|f| if usable[f] { measured[f] } else { given[f] })
            .collect()
    }

    #[test]
    fn too_few_usable_frames_agree_on_nothing() {
        let p = path(5);
        assert!(consensus_poses(&p, &p, &[true, false, true, false, false], 3).is_none());
        let agreed = consensus_poses(&p, &p, &[true, false, true, true, false], 3).unwrap();
        for (a, g) in agreed.iter().zip(&p) {
            assert!(pose_error(a, g).0 < 1e-9);
        }
    }
}
