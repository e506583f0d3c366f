//! [`ShadingKind`]: which shading model — the one name the command line, shading.json,
//! model.json, the cross-validation and the report use for it.

use serde::{Deserialize, Serialize};

/// A shading model bronchosim can fit.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum ShadingKind {
    /// The paper's per-viewpoint Psi (Chung et al. 2004, eq. 2–5).
    Paper,
    /// One calibrated light for the whole video (DESIGN.md, "Beyond the paper").
    Calibrated,
}

impl ShadingKind {
    /// Every model, in the order reports list them.
    pub const ALL: [ShadingKind; 2] = [ShadingKind::Paper, ShadingKind::Calibrated];

    /// The name in files and on the command line ("paper", "calibrated").
    pub fn name(self) -> &'static str {
        match self {
            ShadingKind::Paper => "paper",
            ShadingKind::Calibrated => "calibrated",
        }
    }
}

impl std::fmt::Display for ShadingKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_match_serde_and_clap() {
        use clap::ValueEnum;
        for k in ShadingKind::ALL {
            assert_eq!(
                serde_json::to_string(&k).unwrap(),
                format!("\"{}\"", k.name())
            );
            assert_eq!(ShadingKind::from_str(k.name(), false), Ok(k));
        }
    }
}
