//! Robust losses for iteratively re-weighted least squares (IRLS): the weights that keep
//! vessels, highlights and misregistered pixels from pulling a shading fit.

use serde::{Deserialize, Serialize};

/// Robust loss applied on top of the density weights (IRLS).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Robust {
    /// Plain weighted least squares (the paper).
    None,
    /// Huber: residuals beyond `k` robust standard deviations get weight `k / |t|`. 1.345 is
    /// the usual choice (95% efficiency under Gaussian noise).
    Huber(f64),
    /// Tukey's biweight: residuals beyond `c` robust standard deviations get weight 0.
    /// 4.685 is the usual choice (95% efficiency under Gaussian noise).
    Tukey(f64),
}

impl Robust {
    /// The IRLS weight of a residual `t >= 0` robust standard deviations from the model.
    #[inline]
    pub fn weight(self, t: f64) -> f64 {
        match self {
            Robust::None => 1.0,
            Robust::Huber(k) => {
                if t <= k {
                    1.0
                } else {
                    k / t
                }
            }
            Robust::Tukey(c) => {
                let q = t / c;
                if q < 1.0 {
                    (1.0 - q * q).powi(2)
                } else {
                    0.0
                }
            }
        }
    }
}

impl std::fmt::Display for Robust {
    /// "none", "huber 1.345", "tukey 4.685" (as model.json's light_fit records it).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Robust::None => write!(f, "none"),
            Robust::Huber(k) => write!(f, "huber {k}"),
            Robust::Tukey(c) => write!(f, "tukey {c}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_and_names() {
        assert_eq!(Robust::Huber(1.345).weight(1.0), 1.0);
        assert!((Robust::Huber(1.345).weight(2.69) - 0.5).abs() < 1e-12);
        assert_eq!(Robust::Tukey(4.685).weight(5.0), 0.0);
        assert!((Robust::Tukey(2.0).weight(1.0) - 0.5625).abs() < 1e-12);
        assert_eq!(Robust::None.weight(100.0), 1.0);
        assert_eq!(Robust::Huber(1.345).to_string(), "huber 1.345");
        assert_eq!(Robust::Tukey(4.685).to_string(), "tukey 4.685");
    }
}
