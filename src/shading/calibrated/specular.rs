//! The calibrated light's specular term: `g_f k_c spec_alpha(gamma) s(theta) / z^2`, added to
//! the diffuse `g_f alb_c rho_c(gamma) s(theta) / z^2` and NOT multiplied by the albedo.
//!
//! Mucosa is a wet dielectric: its highlight is light reflected at the surface, before it
//! enters the tissue, so it has the light's colour and no texture. Folded into `rho_c` (as the
//! model did before) a highlight is tinted by the mean albedo and modulated by the vessels.
//!
//! - The lobe's shape is shared by the channels: an isotropic GGX microfacet lobe, the common
//!   model of a rough dielectric, with the light at the lens so the half vector is the view ray
//!   and `n . h = gamma`: `D(gamma) G1(gamma)^2 / (4 gamma)` (the BRDF times the cosine of
//!   incidence; Fresnel is constant near normal incidence), normalised to 1 at gamma = 1. One
//!   shape parameter, alpha; the fit chooses it among [`ALPHA_CANDIDATES`] by its cost.
//! - The colour `k_c` is not tied to rho's: rho's colour is the light's times the mean albedo
//!   (reddish), which is what a highlight must not carry. By default it is white (one k for
//!   the channels): endoscopes are white-balanced on a white target before use, so in the
//!   camera's RGB the light is white, and a free colour lets the lobe stand in for diffuse
//!   light the other terms miss (on the path-traced case it came out red, k = (27, 6, 8), at
//!   the widest alpha). `--specular coloured` fits k_c per channel.

use serde::{Deserialize, Serialize};

/// GGX alphas the fit tries (geometric steps of 1.5 from 0.04): from a glossy wet surface
/// (alpha 0.04: half the peak 1.5 degrees off the normal) to a dull one (0.46: 20 degrees).
/// Beyond that the lobe is as wide as rho's cubic and the two cannot be told apart.
pub const ALPHA_CANDIDATES: [f64; 7] = [0.04, 0.06, 0.09, 0.135, 0.2, 0.3, 0.46];

/// Whether the calibrated light has a specular term, and of which colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpecularMode {
    /// A GGX lobe added to the diffuse light (alpha chosen by the fit) of a white light: one k
    /// for the three channels (endoscopes are white-balanced on a white target before use).
    #[default]
    White,
    /// The same lobe with its colour k_c fitted per channel.
    Coloured,
    /// No separate term: rho holds the highlights, multiplied by the albedo.
    None,
}

/// The fitted specular term, as stored under "calibrated"."specular" in `shading.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpecularLobe {
    /// k_c per channel R, G, B: the highlight at gamma = 1 (linear intensity x mm² at the
    /// reference gain, on the optical axis): the light's colour times the surface reflectance.
    pub k: [f64; 3],
    /// GGX alpha of the lobe (perceptual roughness squared), in (0, 1].
    pub alpha: f64,
}

/// `spec_alpha(gamma)`: the GGX lobe `D G1^2 / (4 gamma)` with n.h = n.l = n.v = gamma,
/// divided by its value at gamma = 1 (so 1 there). Unitless.
#[inline]
pub fn lobe(alpha: f64, gamma: f64) -> f64 {
    let g = gamma.clamp(1e-4, 1.0);
    let a2 = alpha * alpha;
    let den = g * g * (a2 - 1.0) + 1.0;
    // D(g) / D(1) = alpha^4 / den^2.
    let d = a2 * a2 / (den * den);
    let g1 = 2.0 * g / (g + (a2 + (1.0 - a2) * g * g).sqrt());
    d * g1 * g1 / g
}

impl SpecularLobe {
    /// `k_c spec_alpha(gamma)` per channel (linear intensity x mm²).
    #[inline]
    pub fn rgb(&self, gamma: f64) -> [f64; 3] {
        let l = lobe(self.alpha, gamma);
        self.k.map(|k| k * l)
    }

    /// Check a loaded term; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !self.k.iter().all(|k| k.is_finite() && *k >= 0.0) {
            return Err(format!(
                "calibrated.specular.k must be finite and >= 0, got {:?}",
                self.k
            ));
        }
        if !(self.alpha > 0.0 && self.alpha <= 1.0) {
            return Err(format!(
                "calibrated.specular.alpha is {}, must be in (0, 1]",
                self.alpha
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lobe_is_one_at_the_normal_and_matches_ggx() {
        for a in ALPHA_CANDIDATES {
            assert!((lobe(a, 1.0) - 1.0).abs() < 1e-12);
        }
        // The phantom's GGX (alpha 0.09): at 30 degrees below 2% of the peak.
        let l30 = lobe(0.09, 30f64.to_radians().cos());
        assert!(l30 > 0.0 && l30 < 0.02, "{l30}");
        // Half the peak: alpha 0.09 at 3.3 degrees, 0.3 at 11.9.
        let half = |a: f64| {
            (0..9000)
                .map(|i| f64::from(i) * 0.01)
                .find(|d| lobe(a, d.to_radians().cos()) < 0.5)
                .unwrap()
        };
        assert!((half(0.09) - 3.34).abs() < 0.02, "{}", half(0.09));
        assert!((half(0.3) - 11.88).abs() < 0.02, "{}", half(0.3));
        let s = SpecularLobe {
            k: [1.0, 2.0, 3.0],
            alpha: 0.2,
        };
        s.validate().unwrap();
        assert!((s.rgb(1.0)[2] - 3.0).abs() < 1e-12);
        assert!(SpecularLobe { alpha: 0.0, ..s }.validate().is_err());
    }
}
