//! The calibrated light model: one light for the whole video (DESIGN.md, "Beyond the paper").
//!
//! `I_f(pixel) = g_f * (albedo(x) * rho_ch(gamma) + k_ch spec(gamma)) * s(theta) / z^2 (+ a_f,ch)`:
//! rho per colour channel is a Bernstein polynomial in gamma over [0, 1] (it holds the diffuse
//! BRDF and the mean albedo; with `--specular none` the specular lobe too: with the light at
//! the lens the lobe depends on gamma alone); s is the light's angular profile times the lens vignetting, a Bernstein
//! polynomial in cos(theta) shared by the channels with s = 1 on the optical axis; z is the
//! absolute distance (mm, never normalised or clamped); g_f is the frame's auto-exposure gain
//! (1 for the reference frame); a_f the inter-reflected light of frame f: by default
//! `kappa_c · L_f`, three parameters for the video times the frame's mean observed luminance
//! (see `calibrated_fit::CalibratedOptions::interreflection`), or free per frame (`--ambient`);
//! or, with `--interreflection gathered`, `g_f alb(x) k_c E_c(x)` with E gathered from the
//! mesh (`shading::indirect`). `k_ch spec(gamma)` is the highlight, of the light's colour and
//! not multiplied by the albedo ([`super::specular`]; absent with `--specular none`).

use crate::shading::frame_shading::LUMA;
use serde::{Deserialize, Serialize};

use std::sync::Arc;

use super::exposure::AutoExposure;
use super::specular::SpecularLobe;
use crate::shading::bernstein::bernstein_eval;
use crate::shading::indirect::{GatheredInterreflection, IndirectField};

/// The fitted calibrated light model, as stored under "calibrated" in `shading.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibratedModel {
    /// rho per channel R, G, B: Bernstein coefficients in gamma over [0, 1] (degree = length - 1).
    /// Unit: linear intensity x mm² at the reference gain (the inverse-square falloff is
    /// explicit, so rho carries the light's power and the mean albedo).
    pub rho: [Vec<f64>; 3],
    /// s: Bernstein coefficients in `t = (1 - cos theta) / (1 - cos_theta_edge)`, i.e. linear in
    /// cos theta; `s[0] = 1` (s = 1 on the optical axis). Unitless.
    pub s: Vec<f64>,
    /// cos of the largest off-axis angle the fit saw (t = 1). s is held constant beyond it
    /// (never extrapolated). Unitless, in (-1, 1).
    pub cos_theta_edge: f64,
    /// Gain g_f per fitted frame (unitless), `gains[reference_frame] = 1`.
    pub gains: Vec<f64>,
    /// Index of the frame whose gain is fixed to 1.
    pub reference_frame: usize,
    /// Inter-reflected light a_f per fitted frame and channel (linear intensity at that frame's
    /// gain), when the fit kept it (`kappa_c · L_f` by default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient: Option<Vec<[f64; 3]>>,
    /// kappa_c of the inter-reflection term `kappa_c · L_f` (unitless), when the fit had it.
    /// A new view gets `kappa_c` times its own light (see [`Self::view_interreflection`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interreflection: Option<[f64; 3]>,
    /// L_f per fitted frame: its mean observed luminance over its surface pixels (linear
    /// intensity at that frame's gain), when the fit had the inter-reflection term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_light: Option<Vec<f64>>,
    /// The gathered inter-reflection (`--interreflection gathered`): each pixel adds
    /// `g_f alb k_c E_c`, E the light of the frame's own lamp once reflected by the wall,
    /// gathered from the mesh ([`crate::shading::indirect`]); beside `interreflection` or
    /// alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gathered: Option<GatheredInterreflection>,
    /// E of every fitted frame (build time only, not saved: new views gather their own).
    #[serde(skip)]
    pub frame_indirect: Option<Arc<Vec<IndirectField>>>,
    /// The specular term `g_f k_c spec(gamma) s(theta) / z^2` (not multiplied by the albedo);
    /// absent in models built before it, with `--specular none`, or when the fit found none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specular: Option<SpecularLobe>,
    /// The scope's auto-exposure learnt from the gains (see [`AutoExposure`]); absent in models
    /// built before it was fitted, or when the video's frames did not vary in brightness.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub auto_exposure: Option<AutoExposure>,
    /// Weighted RMS residual per channel over the fitted samples (linear intensity), with the
    /// final fit weights (density x robust).
    pub rms_residual: [f64; 3],
    /// Samples the fit used.
    pub samples_used: usize,
}

impl CalibratedModel {
    /// A light of one frame at gain 1 with no inter-reflection or ambient term: `rho` per
    /// channel and `s` as Bernstein coefficients (see the fields), `cos_theta_edge` the edge
    /// of `s`'s domain. For lights known in advance (tests, benchmarks, synthetic cases).
    pub fn new(rho: [Vec<f64>; 3], s: Vec<f64>, cos_theta_edge: f64) -> Self {
        CalibratedModel {
            rho,
            s,
            cos_theta_edge,
            gains: vec![1.0],
            reference_frame: 0,
            ambient: None,
            interreflection: None,
            frame_light: None,
            gathered: None,
            frame_indirect: None,
            specular: None,
            auto_exposure: None,
            rms_residual: [0.0; 3],
            samples_used: 0,
        }
    }

    /// The normalised angle coordinate t of `cos_theta` (0 on the axis, 1 at the edge),
    /// clamped to [0, 1].
    #[inline]
    pub fn t(&self, cos_theta: f64) -> f64 {
        ((1.0 - cos_theta) / (1.0 - self.cos_theta_edge)).clamp(0.0, 1.0)
    }

    /// `rho(gamma)` of channel `ch` (0 = R, 1 = G, 2 = B), linear intensity x mm².
    #[inline]
    pub fn rho(&self, ch: usize, gamma: f64) -> f64 {
        bernstein_eval(&self.rho[ch], gamma)
    }

    /// `s(theta)` given `cos_theta` of the pixel's ray off the optical axis (unitless, 1 on axis).
    #[inline]
    pub fn s(&self, cos_theta: f64) -> f64 {
        bernstein_eval(&self.s, self.t(cos_theta))
    }

    /// Largest off-axis angle the fit saw (degrees).
    pub fn theta_edge_deg(&self) -> f64 {
        self.cos_theta_edge.clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// `gain * rho_ch(gamma) * s(theta) / z^2` (linear intensity), z in mm. Uniform albedo
    /// (folded into rho); no ambient term.
    #[inline]
    pub fn eval(&self, ch: usize, gamma: f64, cos_theta: f64, z: f64, gain: f64) -> f64 {
        gain * self.rho(ch, gamma) * self.s(cos_theta) / (z * z)
    }

    /// [`eval`](Self::eval) for R, G, B at once.
    #[inline]
    pub fn eval_rgb(&self, gamma: f64, cos_theta: f64, z: f64, gain: f64) -> [f64; 3] {
        let k = gain * self.s(cos_theta) / (z * z);
        std::array::from_fn(|ch| k * self.rho(ch, gamma))
    }

    /// The specular term `gain k_c spec(gamma) s(theta) / z^2` per channel (linear intensity;
    /// zeros without one): light added to the albedo-scaled [`eval_rgb`](Self::eval_rgb).
    #[inline]
    pub fn specular_rgb(&self, gamma: f64, cos_theta: f64, z: f64, gain: f64) -> [f64; 3] {
        let Some(sp) = &self.specular else {
            return [0.0; 3];
        };
        let k = gain * self.s(cos_theta) / (z * z);
        sp.rgb(gamma).map(|v| k * v)
    }

    /// The shading of fitted frame `frame` in channel `ch` for the mean albedo: its gain, its
    /// specular term and its ambient term if any.
    /// `None` when `frame` was not fitted.
    pub fn eval_frame(
        &self,
        ch: usize,
        gamma: f64,
        cos_theta: f64,
        z: f64,
        frame: usize,
    ) -> Option<f64> {
        let g = *self.gains.get(frame)?;
        Some(
            self.eval(ch, gamma, cos_theta, z, g)
                + self.specular_rgb(gamma, cos_theta, z, g)[ch]
                + self.ambient_of(frame)[ch],
        )
    }

    /// a_f of fitted frame `frame` (zeros without an ambient term or for an unknown frame).
    pub fn ambient_of(&self, frame: usize) -> [f64; 3] {
        self.ambient
            .as_ref()
            .and_then(|a| a.get(frame).copied())
            .unwrap_or([0.0; 3])
    }

    /// The part of a new view's ambient term that does not depend on its light, at the
    /// reference gain: the median over fitted frames of `(a_f - kappa L_f) / g_f` per channel,
    /// i.e. the free per-frame term when fitted (zeros without one).
    pub fn new_view_ambient(&self) -> [f64; 3] {
        let Some(a) = &self.ambient else {
            return [0.0; 3];
        };
        std::array::from_fn(|ch| {
            let mut v: Vec<f64> = a
                .iter()
                .zip(&self.gains)
                .enumerate()
                .map(|(f, (a, g))| (a[ch] - self.interreflection_of(f)[ch]) / g.max(1e-300))
                .collect();
            if v.is_empty() {
                return 0.0;
            }
            let mid = v.len() / 2;
            *v.select_nth_unstable_by(mid, |x, y| x.total_cmp(y)).1
        })
    }

    /// `kappa_c L_f` of fitted frame `frame` (zeros without the inter-reflection term).
    fn interreflection_of(&self, frame: usize) -> [f64; 3] {
        match (&self.interreflection, &self.frame_light) {
            (Some(k), Some(l)) => {
                let light = l.get(frame).copied().unwrap_or(0.0);
                k.map(|k| k * light)
            }
            _ => [0.0; 3],
        }
    }

    /// The light inter-reflected in a new view at the reference gain, `kappa_c L` (zeros
    /// without the term), where L is the view's mean luminance over its surface pixels,
    /// inter-reflection included: `L = L0 + (sum_c LUMA_c kappa_c) L`, with `light_without` =
    /// L0 the mean luminance of the view's direct light plus [`Self::new_view_ambient`]. The
    /// light moves with the camera, so a view close to the wall holds more light than one
    /// down a wide airway.
    pub fn view_interreflection(&self, light_without: f64) -> [f64; 3] {
        let Some(k) = self.interreflection else {
            return [0.0; 3];
        };
        let k_lum: f64 = (0..3).map(|c| LUMA[c] * k[c]).sum();
        // kappa is a few percent; the bound only guards a degenerate fit.
        let light = light_without.max(0.0) / (1.0 - k_lum).max(0.05);
        k.map(|k| k * light)
    }
    /// The albedo (relative to the mean albedo folded into rho) that de-lights `value` (linear
    /// intensity) seen in fitted frame `frame`: `(value - a_f - specular) / (g_f rho s / z^2)`.
    /// `None` for an unknown frame or a non-positive shading.
    pub fn delight(
        &self,
        ch: usize,
        value: f64,
        gamma: f64,
        cos_theta: f64,
        z: f64,
        frame: usize,
    ) -> Option<f64> {
        let g = *self.gains.get(frame)?;
        let shade = self.eval(ch, gamma, cos_theta, z, g);
        let spec = self.specular_rgb(gamma, cos_theta, z, g)[ch];
        (shade > 0.0).then(|| (value - self.ambient_of(frame)[ch] - spec) / shade)
    }

    /// Check the invariants a loaded model must hold; the message says which field is wrong.
    pub fn validate(&self) -> Result<(), String> {
        for (ch, r) in self.rho.iter().enumerate() {
            if r.is_empty() || r.len() > 16 || r.iter().any(|v| !v.is_finite()) {
                return Err(format!(
                    "calibrated.rho[{ch}]: expected 1..16 finite coefficients, got {:?}",
                    r
                ));
            }
        }
        if self.s.is_empty() || self.s.len() > 16 || self.s.iter().any(|v| !v.is_finite()) {
            return Err(format!(
                "calibrated.s: expected 1..16 finite coefficients, got {:?}",
                self.s
            ));
        }
        if self.s[0] != 1.0 {
            return Err(format!(
                "calibrated.s[0] is {}, must be 1 (s = 1 on the axis)",
                self.s[0]
            ));
        }
        if !(self.cos_theta_edge > -1.0 && self.cos_theta_edge < 1.0) {
            return Err(format!(
                "calibrated.cos_theta_edge is {}, must be in (-1, 1)",
                self.cos_theta_edge
            ));
        }
        if self.gains.iter().any(|g| !(g.is_finite() && *g > 0.0)) {
            return Err("calibrated.gains: every gain must be finite and > 0".into());
        }
        if self.reference_frame >= self.gains.len().max(1) {
            return Err(format!(
                "calibrated.reference_frame {} is out of range ({} gains)",
                self.reference_frame,
                self.gains.len()
            ));
        }
        for (name, len) in [
            ("ambient", self.ambient.as_ref().map(Vec::len)),
            ("frame_light", self.frame_light.as_ref().map(Vec::len)),
        ] {
            if let Some(len) = len.filter(|&l| l != self.gains.len()) {
                return Err(format!(
                    "calibrated.{name} has {len} entries for {} gains",
                    self.gains.len()
                ));
            }
        }
        if let Some(ae) = &self.auto_exposure {
            ae.validate()?;
        }
        if let Some(g) = &self.gathered {
            g.validate()?;
        }
        if let Some(sp) = &self.specular {
            sp.validate()?;
        }
        if self.interreflection.is_some() != self.frame_light.is_some() {
            return Err(
                "calibrated.interreflection and calibrated.frame_light go together".to_string(),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eval_is_inverse_square_and_one_on_axis() {
        let m = CalibratedModel {
            gains: vec![1.0, 2.0],
            ambient: Some(vec![[0.0; 3], [0.01, 0.02, 0.03]]),
            ..CalibratedModel::new(
                [vec![0.0, 10.0, 20.0, 30.0], vec![1.0; 4], vec![2.0; 2]],
                vec![1.0, 0.8, 0.5, 0.2],
                0.5,
            )
        };
        m.validate().unwrap();
        // On the axis s = 1; at gamma = 1 rho_R = 30; z = 10 mm → 0.3.
        assert!((m.eval(0, 1.0, 1.0, 10.0, 1.0) - 0.3).abs() < 1e-15);
        assert!((m.eval(0, 1.0, 1.0, 20.0, 1.0) - 0.075).abs() < 1e-15);
        // At the edge (cos = 0.5) s = 0.2; beyond it clamped.
        assert!((m.s(0.5) - 0.2).abs() < 1e-15);
        assert_eq!(m.s(0.1), m.s(0.5));
        // Frame 1: gain 2 plus ambient; delight inverts it.
        let v = m.eval_frame(2, 0.4, 0.9, 7.0, 1).unwrap();
        assert!((v - (2.0 * 2.0 * m.s(0.9) / 49.0 + 0.03)).abs() < 1e-15);
        assert!((m.delight(2, v, 0.4, 0.9, 7.0, 1).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(m.new_view_ambient()[1], 0.01);
        let json = serde_json::to_string(&m).unwrap();
        let back: CalibratedModel = serde_json::from_str(&json).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn an_older_model_loads_and_a_gathered_one_keeps_its_factor() {
        // shading.json's calibrated light as written before the gathered inter-reflection.
        let old = r#"{"rho": [[1.0, 2.0], [1.0, 2.0], [0.5, 1.0]], "s": [1.0, 0.8],
            "cos_theta_edge": 0.5, "gains": [1.0, 1.2], "reference_frame": 0,
            "ambient": [[0.01, 0.01, 0.01], [0.02, 0.02, 0.02]],
            "interreflection": [0.05, 0.05, 0.05], "frame_light": [0.2, 0.4],
            "rms_residual": [0.0, 0.0, 0.0], "samples_used": 10}"#;
        let m: CalibratedModel = serde_json::from_str(old).unwrap();
        m.validate().unwrap();
        assert!(m.gathered.is_none() && m.frame_indirect.is_none());
        let g = GatheredInterreflection {
            k: [0.6, 0.5, 0.4],
            nodes_across: 40,
            rays: 36,
            visibility: false,
        };
        let gathered = CalibratedModel {
            ambient: None,
            interreflection: None,
            frame_light: None,
            gathered: Some(g),
            frame_indirect: Some(Arc::new(Vec::new())),
            ..m.clone()
        };
        gathered.validate().unwrap();
        let json = serde_json::to_string(&gathered).unwrap();
        let back: CalibratedModel = serde_json::from_str(&json).unwrap();
        // The factor is saved; the frames' gathered light is build-time only.
        assert_eq!(back.gathered, Some(g));
        assert!(back.frame_indirect.is_none());
        let negative = CalibratedModel {
            gathered: Some(GatheredInterreflection {
                k: [-0.1, 0.5, 0.4],
                ..g
            }),
            ..gathered
        };
        assert!(negative.validate().unwrap_err().contains("gathered.k"));
    }

    #[test]
    fn a_new_view_reflects_its_own_light() {
        // Two frames: kappa L_f plus a free term of 0.01 per unit gain in every channel.
        let kappa = [0.05, 0.04, 0.03];
        let light = [0.2, 0.3];
        let gains = vec![1.0, 2.0];
        let ambient = (0..2)
            .map(|f| std::array::from_fn(|c| kappa[c] * light[f] + 0.01 * gains[f]))
            .collect();
        let m = CalibratedModel {
            gains,
            ambient: Some(ambient),
            interreflection: Some(kappa),
            frame_light: Some(light.to_vec()),
            ..CalibratedModel::new(
                [vec![1.0; 4], vec![1.0; 4], vec![1.0; 4]],
                vec![1.0, 1.0],
                0.5,
            )
        };
        m.validate().unwrap();
        // The part that does not move with the light: the free term alone.
        for a in m.new_view_ambient() {
            assert!((a - 0.01).abs() < 1e-12, "{a}");
        }
        // A view whose direct light (plus that term) averages 0.4: its mean luminance L with
        // the inter-reflection satisfies L = 0.4 + sum_c LUMA_c kappa_c L.
        let a = m.view_interreflection(0.4);
        let l = 0.4 + (0..3).map(|c| LUMA[c] * a[c]).sum::<f64>();
        for c in 0..3 {
            assert!((a[c] - kappa[c] * l).abs() < 1e-12, "channel {c}");
        }
        // Twice the light, twice the inter-reflection.
        let b = m.view_interreflection(0.8);
        assert!((b[1] / a[1] - 2.0).abs() < 1e-12);
        // Without the term nothing moves with the view's light.
        let plain = CalibratedModel {
            interreflection: None,
            frame_light: None,
            ..m.clone()
        };
        assert_eq!(plain.view_interreflection(0.4), [0.0; 3]);
        let mut bad = m.clone();
        bad.frame_light = None;
        assert!(bad.validate().is_err());
    }
}
