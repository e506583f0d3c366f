//! What of the wall one frame sees, and how well: the atlas is cut into square cells of about
//! a millimetre (so a coarse ray grid samples every cell it sees, which texels would alias),
//! and each cell a frame sees gets the quality of its best view of it:
//! `min(1, gamma · (f · texel / z)²)`, the share of the texel's resolution the frame resolves
//! (projected texel area in pixels at full resolution, capped where the frame samples finer
//! than the texture stores), times the cosine between the view and the wall's normal.

/// The coverage cells of an atlas.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoverageGrid {
    /// Atlas width (texels).
    pub atlas_width: u32,
    /// Atlas height (texels).
    pub atlas_height: u32,
    /// Cell edge (texels).
    pub cell_texels: u32,
}

impl CoverageGrid {
    /// Cells of about `cell_mm` (at least one texel) on an atlas of `width` × `height` texels
    /// of `texel_mm`.
    pub fn new(width: u32, height: u32, texel_mm: f64, cell_mm: f64) -> CoverageGrid {
        CoverageGrid {
            atlas_width: width,
            atlas_height: height,
            cell_texels: ((cell_mm / texel_mm).round() as u32).max(1),
        }
    }

    fn columns(&self) -> u32 {
        self.atlas_width.div_ceil(self.cell_texels)
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.columns() as usize * self.atlas_height.div_ceil(self.cell_texels) as usize
    }

    /// The cell holding atlas coordinate `uv` (in [0, 1]², texel x covers [x/w, (x+1)/w]).
    pub fn cell_of(&self, uv: [f32; 2]) -> Option<u32> {
        let x = (uv[0] * self.atlas_width as f32).floor();
        let y = (uv[1] * self.atlas_height as f32).floor();
        if !(x >= 0.0 && y >= 0.0 && x < self.atlas_width as f32 && y < self.atlas_height as f32) {
            return None;
        }
        let (cx, cy) = (x as u32 / self.cell_texels, y as u32 / self.cell_texels);
        Some(cy * self.columns() + cx)
    }
}

/// One ray's view of the wall.
#[derive(Clone, Copy, Debug)]
pub struct WallHit {
    /// Atlas coordinate of the hit.
    pub uv: [f32; 2],
    /// Distance from the camera centre (mm).
    pub z: f32,
    /// Cosine between the direction to the camera and the wall's normal.
    pub gamma: f32,
}

/// The cells one frame sees, each with the quality of its best view (increasing cell ids).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameCoverage {
    /// Cell ids, increasing.
    pub cells: Vec<u32>,
    /// Quality in (0, 1] of each cell's view.
    pub quality: Vec<f32>,
}

impl FrameCoverage {
    /// The coverage of a frame from its rays' `hits`; `focal_px` is the full-resolution focal
    /// length (pixels) and `texel_mm` the atlas's texel.
    pub fn from_hits(
        hits: impl IntoIterator<Item = WallHit>,
        grid: &CoverageGrid,
        focal_px: f64,
        texel_mm: f64,
    ) -> FrameCoverage {
        let ft = (focal_px * texel_mm) as f32;
        let mut seen: Vec<(u32, f32)> = hits
            .into_iter()
            .filter(|h| h.z > 0.0 && h.z.is_finite() && h.gamma > 0.0)
            .filter_map(|h| {
                let q = (h.gamma * (ft / h.z).powi(2)).min(1.0);
                grid.cell_of(h.uv).map(|c| (c, q))
            })
            .collect();
        seen.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
        seen.dedup_by_key(|s| s.0);
        FrameCoverage {
            cells: seen.iter().map(|s| s.0).collect(),
            quality: seen.iter().map(|s| s.1).collect(),
        }
    }

    /// Sum of the qualities (the frame's value on an empty wall).
    pub fn total(&self) -> f64 {
        self.quality.iter().map(|&q| q as f64).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_keep_the_best_view_and_quality_follows_distance_and_angle() {
        // 100 x 50 texels of 0.1 mm, cells of 1 mm = 10 texels: 10 x 5 cells.
        let g = CoverageGrid::new(100, 50, 0.1, 1.0);
        assert_eq!(g.cells(), 50);
        assert_eq!(g.cell_of([0.0, 0.0]), Some(0));
        assert_eq!(g.cell_of([0.555, 0.5]), Some(2 * 10 + 5));
        assert_eq!(g.cell_of([1.0, 0.5]), None);
        let hit = |u: f32, z: f32, gamma: f32| WallHit {
            uv: [u, 0.01],
            z,
            gamma,
        };
        // f · texel = 200 px · 0.1 mm = 20 mm: at 40 mm, frontal, a quarter of the resolution.
        let c = FrameCoverage::from_hits(
            [
                hit(0.05, 40.0, 1.0),
                hit(0.01, 80.0, 1.0),
                hit(0.35, 20.0, 0.5),
            ],
            &g,
            200.0,
            0.1,
        );
        assert_eq!(c.cells, vec![0, 3]);
        assert_eq!(c.quality, vec![0.25, 0.5]);
        assert!((c.total() - 0.75).abs() < 1e-9);
    }
}
