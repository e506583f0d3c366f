//! The bronchoscope's auto-exposure, learnt from the calibrated light's per-frame gains.
//!
//! Each fitted frame f has a gain g_f (relative to the reference frame) and a mean observed
//! luminance L_f over its surface pixels (at that gain). `L_f / g_f` is the brightness the
//! frame's view would have at the reference gain, i.e. what the scope's exposure control saw
//! before it reacted. The scope's response is fitted as a power law,
//! `log g = a + b log(L / g)` (least squares over the frames; b = -1 is a controller that holds
//! the mean brightness constant, b = 0 a fixed exposure). A new view rendered at the reference
//! gain with mean luminance L then gets the gain `exp(a) L^b`, with L clamped to the range the
//! video covered (the response is never extrapolated).

use serde::{Deserialize, Serialize};

/// The fitted exposure response, as stored in shading.json (`calibrated.auto_exposure`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutoExposure {
    /// a: log of the gain at unit brightness (natural log, gain relative to the reference frame).
    pub log_gain_at_unit_light: f64,
    /// b: d log(gain) / d log(brightness at the reference gain). Unitless; -1 holds the mean
    /// brightness constant.
    pub slope: f64,
    /// Smallest and largest brightness at the reference gain among the fitted frames (mean
    /// linear luminance over surface pixels); a new view's brightness is clamped to this range.
    pub light_range: [f64; 2],
    /// RMS of the fit's residuals in log gain (natural log; 0.1 is about 10% in gain).
    pub rms_log_residual: f64,
    /// Frames the fit used.
    pub frames_used: usize,
}

/// Frames needed for a fit: two parameters and at least one degree of freedom to judge it.
const MIN_FRAMES: usize = 3;

impl AutoExposure {
    /// Fit the response to `gains` (g_f, relative to the reference frame) and `frame_light`
    /// (L_f, mean observed luminance over each frame's surface pixels at its own gain), in frame
    /// order. Frames with a non-positive or non-finite value are left out. `None` with fewer
    /// than 3 usable frames or when every frame saw the same brightness (no slope to fit).
    pub fn fit(gains: &[f64], frame_light: &[f64]) -> Option<AutoExposure> {
        let pts: Vec<(f64, f64)> = gains
            .iter()
            .zip(frame_light)
            .filter(|(g, l)| g.is_finite() && l.is_finite() && **g > 0.0 && **l > 0.0)
            .map(|(g, l)| ((l / g).ln(), g.ln()))
            .collect();
        if pts.len() < MIN_FRAMES {
            return None;
        }
        let n = pts.len() as f64;
        let (mx, my) = pts
            .iter()
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
        let sxx: f64 = pts.iter().map(|(x, _)| (x - mx) * (x - mx)).sum();
        let sxy: f64 = pts.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
        // A spread below 0.1% in brightness cannot tell a slope from noise.
        if sxx <= n * 1e-6 {
            return None;
        }
        let slope = sxy / sxx;
        let a = my - slope * mx;
        let rss: f64 = pts.iter().map(|(x, y)| (y - a - slope * x).powi(2)).sum();
        let (lo, hi) = pts
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), (x, _)| {
                (lo.min(x.exp()), hi.max(x.exp()))
            });
        Some(AutoExposure {
            log_gain_at_unit_light: a,
            slope,
            light_range: [lo, hi],
            rms_log_residual: (rss / n).sqrt(),
            frames_used: pts.len(),
        })
    }

    /// The gain (relative to the reference frame) the scope would choose for a view whose mean
    /// luminance over its surface pixels is `light` at the reference gain (clamped to
    /// [`Self::light_range`]; a view that sees no surface gets the gain of the darkest frame).
    pub fn gain(&self, light: f64) -> f64 {
        let [lo, hi] = self.light_range;
        let l = if light.is_finite() && light > 0.0 {
            light.clamp(lo, hi)
        } else {
            lo
        };
        (self.log_gain_at_unit_light + self.slope * l.ln()).exp()
    }

    /// Check the invariants a loaded model must hold; the message says which field is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let [lo, hi] = self.light_range;
        if !(self.log_gain_at_unit_light.is_finite() && self.slope.is_finite()) {
            return Err("calibrated.auto_exposure: the coefficients must be finite".into());
        }
        if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
            return Err(format!(
                "calibrated.auto_exposure.light_range [{lo}, {hi}] must be positive and ordered"
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64 as Rng;

    #[test]
    fn recovers_a_known_power_law_from_noisy_gains() {
        // A scope that answers brightness L (at the reference gain) with g = 0.3 L^-0.8,
        // observed with 3% log-normal noise on the gain.
        let mut rng = Rng::new(7);
        let mut gains = Vec::new();
        let mut light = Vec::new();
        for _ in 0..200 {
            let l_unit = (rng.uniform() * 3.0 - 2.5).exp(); // e^-2.5 .. e^0.5
            let g = 0.3 * l_unit.powf(-0.8) * (0.03 * rng.normal()).exp();
            gains.push(g);
            light.push(l_unit * g); // observed at the frame's own gain
        }
        let ae = AutoExposure::fit(&gains, &light).unwrap();
        assert!((ae.slope + 0.8).abs() < 0.02, "slope {}", ae.slope);
        assert!((ae.log_gain_at_unit_light - 0.3f64.ln()).abs() < 0.03);
        assert!(
            (ae.rms_log_residual - 0.03).abs() < 0.006,
            "{}",
            ae.rms_log_residual
        );
        assert_eq!(ae.frames_used, 200);
        ae.validate().unwrap();
        // Inside the range: the law; outside: clamped.
        let l = 0.2;
        assert!((ae.gain(l) / (0.3 * 0.2f64.powf(-0.8)) - 1.0).abs() < 0.03);
        assert_eq!(ae.gain(1e-9), ae.gain(ae.light_range[0]));
        assert_eq!(ae.gain(f64::NAN), ae.gain(ae.light_range[0]));
        assert_eq!(ae.gain(1e9), ae.gain(ae.light_range[1]));
    }

    #[test]
    fn too_few_frames_or_no_spread_fit_nothing() {
        assert!(AutoExposure::fit(&[1.0, 2.0], &[0.1, 0.2]).is_none());
        // Every frame at the same brightness: no slope.
        assert!(AutoExposure::fit(&[1.0, 2.0, 4.0], &[0.1, 0.2, 0.4]).is_none());
        // Unusable frames are left out.
        assert!(AutoExposure::fit(&[1.0, 0.0, f64::NAN, 2.0], &[0.1; 4]).is_none());
    }
}
