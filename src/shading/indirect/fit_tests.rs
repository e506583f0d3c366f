//! The calibrated fit with the gathered inter-reflection recovers a known factor k_c.

use crate::rng::Pcg32;
use crate::shading::bernstein::bernstein_eval;
use crate::shading::calibrated::{fit_calibrated, CalibratedOptions, PooledSamples};
use crate::shading::Robust;

#[test]
fn fit_recovers_a_known_gathered_factor() {
    recover(false);
}

#[test]
fn fit_recovers_the_gathered_factor_beside_kappa() {
    recover(true);
}

/// Samples of a light with a gathered term (and, when `with_kappa`, `kappa_c L_f` beside it);
/// the fit must give back k (and kappa) and the gains.
fn recover(with_kappa: bool) {
    let kappa = [0.05, 0.03, 0.02];
    let frame_light = [0.10, 0.25, 0.15, 0.30];
    let rho = [
        vec![0.4, 1.2, 1.8, 2.0],
        vec![0.3, 0.8, 1.1, 1.3],
        vec![0.1, 0.4, 0.6, 0.7],
    ];
    let s = [1.0, 0.9, 0.75, 0.6];
    let gains = [1.0, 1.3, 0.8, 1.1];
    let k = [0.6, 0.45, 0.3];
    let cos_edge = 0.55;
    let mut rng = Pcg32::new(3, 0);
    let mut p = PooledSamples {
        frame_start: vec![0],
        ..Default::default()
    };
    let mut e: [Vec<f32>; 3] = Default::default();
    for (f, g) in gains.iter().enumerate() {
        for i in 0..3000 {
            let gamma = rng.range(0.3, 1.0);
            let cos_t = rng.range(cos_edge, 1.0);
            let z = rng.range(4.0, 40.0);
            // A gathered light that grows with depth relative to the direct light (a tube).
            let light = 0.004 * (1.0 + z / 15.0) * rng.range(0.8, 1.2);
            let t = (1.0 - cos_t) / (1.0 - cos_edge);
            let direct = bernstein_eval(&s, t) / (z * z);
            p.gamma.push(gamma as f32);
            p.cos_theta.push(cos_t as f32);
            p.z.push(z as f32);
            p.frame.push(f as u32);
            p.pixel.push(i);
            p.neighbour_chroma.push([f32::NAN; 2]);
            for c in 0..3 {
                let el = light * [1.0, 0.7, 0.5][c];
                e[c].push(el as f32);
                let mut v = g * (bernstein_eval(&rho[c], gamma) * direct + k[c] * el);
                if with_kappa {
                    v += kappa[c] * frame_light[f];
                }
                p.rgb[c].push(v as f32);
            }
        }
        p.frame_start.push(p.gamma.len());
        p.excluded.push(Default::default());
        p.frame_light.push(frame_light[f]);
    }
    p.indirect = Some(e);
    let opts = CalibratedOptions {
        gathered: true,
        interreflection: with_kappa,
        robust: Robust::None,
        ..Default::default()
    };
    let density = vec![1.0f32; p.len()];
    let m = fit_calibrated(&p, &density, &opts).unwrap().model;
    let got = m.gathered.expect("the gathered factor").k;
    for c in 0..3 {
        assert!((got[c] / k[c] - 1.0).abs() < 0.01, "k {got:?} vs {k:?}");
    }
    for (f, g) in gains.iter().enumerate() {
        assert!((m.gains[f] / g - 1.0).abs() < 0.005, "gains {:?}", m.gains);
    }
    match m.interreflection {
        Some(got) if with_kappa => {
            for c in 0..3 {
                assert!((got[c] / kappa[c] - 1.0).abs() < 0.01, "kappa {got:?}");
            }
        }
        None if !with_kappa => assert!(m.ambient.is_none()),
        other => panic!("kappa {other:?} (fitted: {with_kappa})"),
    }
    // Without the samples' gathered light the gathered fit refuses to run.
    p.indirect = None;
    assert!(fit_calibrated(&p, &density, &opts).is_err());
}
