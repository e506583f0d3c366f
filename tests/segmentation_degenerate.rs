//! Segmentation and the lumen mesh end on every input: random and degenerate volumes (all NaN,
//! all air, all tissue, constant, 1x1x1, thin slabs, noise, huge and infinite values), with the
//! automatic seed and with a given one, each end with `Ok` or a one-line `Err` within a time
//! bound; and non-finite voxels count as tissue, so a NaN block leaves the tree intact.

use bronchosim::math::{Affine, Point3};
use bronchosim::phantom::{make_ct_phantom, CtPhantomOptions};
use bronchosim::volume::segment::SegmentOptions;
use bronchosim::volume::Volume;
use bronchosim::workflow::segment::{segment_and_mesh, SegmentCommandOptions};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Generous for the debug profile on a shared machine; a normal case takes well under a second.
const TIME_LIMIT: Duration = Duration::from_secs(20);

/// Segment and mesh `ct` on another thread; `Ok((volume ml, threshold HU))` or `Err(message)`.
/// Fails the test when the run panics or does not end within [`TIME_LIMIT`].
fn run(name: &str, ct: Volume<f32>, seed: Option<Point3<f64>>) -> Result<(f64, f32), String> {
    let (tx, rx) = mpsc::channel();
    let t = Instant::now();
    std::thread::spawn(move || {
        let opts = SegmentCommandOptions {
            segment: SegmentOptions {
                seed_world: seed,
                ..Default::default()
            },
            ..Default::default()
        };
        let r = segment_and_mesh(&ct, &opts);
        let _ = tx.send(r.map(|(seg, mesh, _, _)| {
            assert!(mesh
                .positions
                .iter()
                .all(|p| p.coords.iter().all(|c| c.is_finite())));
            (seg.volume_ml, seg.threshold_hu)
        }));
    });
    let r = match rx.recv_timeout(TIME_LIMIT) {
        Ok(r) => r.map_err(|e| e.to_string()),
        Err(mpsc::RecvTimeoutError::Timeout) => {
            panic!("{name}: still running after {TIME_LIMIT:?}")
        }
        Err(mpsc::RecvTimeoutError::Disconnected) => panic!("{name}: panicked"),
    };
    println!(
        "{name} (seed {seed:?}): {r:?} in {:.2} s",
        t.elapsed().as_secs_f64()
    );
    if let Err(e) = &r {
        assert!(!e.is_empty() && !e.contains('\n'), "{name}: error {e:?}");
    }
    r
}

fn volume(dims: [usize; 3], f: impl Fn(usize, [usize; 3]) -> f32) -> Volume<f32> {
    let mut a = Affine::identity();
    a[(0, 0)] = -0.8;
    a[(1, 1)] = -0.8;
    a[(2, 2)] = 1.2;
    let data = (0..dims[0] * dims[1] * dims[2])
        .map(|n| {
            let ijk = [
                n % dims[0],
                (n / dims[0]) % dims[1],
                n / (dims[0] * dims[1]),
            ];
            f(n, ijk)
        })
        .collect();
    Volume::from_data(dims, a, data).unwrap()
}

/// A seeded hash to [0, 1): noise that needs no RNG state.
fn hash01(n: usize, salt: u64) -> f32 {
    let x = bronchosim::rng::splitmix64(n as u64 ^ salt.rotate_left(32));
    (x >> 40) as f32 / (1u64 << 24) as f32
}

#[test]
fn degenerate_volumes_end_with_ok_or_a_clear_error() {
    let d = [32, 30, 28];
    let tube = |ijk: [usize; 3]| {
        let (x, y) = (ijk[0] as f32 - 15.5, ijk[1] as f32 - 14.5);
        x * x + y * y < 25.0
    };
    let slab = |air: bool| if air { -1000.0 } else { 40.0 };
    let cases: Vec<(&str, Volume<f32>, bool)> = vec![
        ("all NaN", volume(d, |_, _| f32::NAN), false),
        ("all +inf", volume(d, |_, _| f32::INFINITY), false),
        ("all -inf", volume(d, |_, _| f32::NEG_INFINITY), false),
        ("all air", volume(d, |_, _| -1000.0), false),
        ("all tissue", volume(d, |_, _| 40.0), false),
        ("constant 0", volume(d, |_, _| 0.0), false),
        ("1x1x1 air", volume([1, 1, 1], |_, _| -1000.0), false),
        ("2x2x2 air", volume([2, 2, 2], |_, _| -1000.0), false),
        (
            "one slice",
            volume([32, 30, 1], |_, [i, j, _]| slab(tube([i, j, 0]))),
            false,
        ),
        (
            "three slices",
            volume([32, 30, 3], |_, [i, j, _]| slab(tube([i, j, 0]))),
            true,
        ),
        (
            "one voxel wide",
            volume([1, 30, 28], |_, [_, j, _]| slab(j == 15)),
            false,
        ),
        (
            "noise",
            volume(d, |n, _| -1100.0 + 1300.0 * hash01(n, 1)),
            true,
        ),
        (
            "NaN noise in a tube",
            volume(d, |n, ijk| {
                if hash01(n, 2) < 0.3 {
                    f32::NAN
                } else if tube(ijk) {
                    -1000.0
                } else {
                    40.0
                }
            }),
            true,
        ),
        (
            "huge values in a tube",
            volume(d, |n, ijk| {
                if tube(ijk) {
                    -1e30 * (1.0 + hash01(n, 3))
                } else if hash01(n, 4) < 0.5 {
                    f32::MAX
                } else {
                    1e30
                }
            }),
            true,
        ),
        (
            "infinite tube",
            volume(d, |_, ijk| {
                if tube(ijk) {
                    f32::NEG_INFINITY
                } else {
                    f32::INFINITY
                }
            }),
            true,
        ),
    ];
    for (name, ct, can_succeed) in cases {
        let centre = ct.index_to_world(Point3::new(
            (ct.dims[0] / 2) as f64,
            (ct.dims[1] / 2) as f64,
            (ct.dims[2] / 2) as f64,
        ));
        for seed in [None, Some(centre)] {
            let r = run(name, ct.clone(), seed);
            if !can_succeed {
                assert!(r.is_err(), "{name}: expected an error, got {r:?}");
            }
        }
    }
}

/// A block of NaN in the trachea (touching its wall) counts as tissue: the threshold is kept and
/// the airway loses at most the block's voxels.
#[test]
fn nan_block_counts_as_tissue() {
    let ph = make_ct_phantom(&CtPhantomOptions::coarse()).unwrap();
    let (clean_ml, clean_hu) = run("clean phantom", ph.ct.clone(), None).unwrap();
    let mut ct = ph.ct.clone();
    let c = ph.tree.carina();
    let at = ph
        .ct
        .voxel_at_world(Point3::new(c.x, c.y, c.z + 30.0))
        .unwrap();
    let mut blocked = 0usize;
    for k in at[2] - 5..at[2] + 5 {
        for j in at[1] - 5..at[1] + 5 {
            for i in at[0] - 5..at[0] + 5 {
                blocked += usize::from(ph.truth_mask.get(i, j, k) != 0);
                ct.set(i, j, k, f32::NAN);
            }
        }
    }
    assert!(
        blocked > 100,
        "the block must cover trachea voxels ({blocked})"
    );
    let (ml, hu) = run("phantom with a NaN block", ct, None).unwrap();
    let sp = ph.ct.spacing();
    let lost = (clean_ml - ml) / (sp[0] * sp[1] * sp[2] / 1000.0);
    println!("lost {lost:.0} voxels, {blocked} trachea voxels set to NaN");
    assert_eq!(hu, clean_hu);
    assert!(
        (0.0..=1000.0).contains(&lost),
        "lost {lost:.0} voxels to a block of 1000 NaN ({blocked} in the trachea)"
    );
}
