//! What can go wrong in the volume layer: grids, segmentation, marching cubes, paths.

/// A voxel index (i, j, k) as messages print it.
fn ijk(v: &[usize; 3]) -> String {
    format!("({}, {}, {})", v[0], v[1], v[2])
}

/// A grid size as messages print it.
fn grid(d: &[usize; 3]) -> String {
    format!("{} x {} x {}", d[0], d[1], d[2])
}

/// A volume operation that cannot be done on these inputs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VolumeError {
    /// Voxel data whose length does not match the grid.
    #[error("volume data has {got} values, but a {} grid needs {}", grid(.dims), .dims[0] * .dims[1] * .dims[2])]
    DataLength {
        /// Values given.
        got: usize,
        /// Grid size.
        dims: [usize; 3],
    },
    /// An index→world affine that cannot place voxels.
    #[error("volume affine is singular or not finite")]
    SingularAffine,
    /// Two volumes that must share a grid do not.
    #[error("{stage}: {what} grid {} differs from the CT's {}", grid(.got), grid(.expected))]
    GridMismatch {
        /// Which operation.
        stage: &'static str,
        /// Which volume.
        what: &'static str,
        /// Its grid.
        got: [usize; 3],
        /// The grid expected.
        expected: [usize; 3],
    },
    /// A grid too large for 32-bit voxel indices.
    #[error("{stage}: a {} grid has more than 2^32 voxels", grid(.dims))]
    GridTooLarge {
        /// Which operation.
        stage: &'static str,
        /// Grid size.
        dims: [usize; 3],
    },
    /// A seed voxel outside the grid.
    #[error("region growing: seed voxel {} is outside the {} grid", ijk(.seed), grid(.dims))]
    SeedOutsideGrid {
        /// Seed voxel.
        seed: [usize; 3],
        /// Grid size.
        dims: [usize; 3],
    },
    /// A seed point (world mm) outside the CT.
    #[error("seed ({:.1}, {:.1}, {:.1}) mm is outside the CT, which spans ({:.1}, {:.1}, {:.1})..({:.1}, {:.1}, {:.1}) mm", .seed[0], .seed[1], .seed[2], .lo[0], .lo[1], .lo[2], .hi[0], .hi[1], .hi[2])]
    SeedOutsideCt {
        /// Seed (world mm).
        seed: [f64; 3],
        /// Lowest world corner of the CT (mm).
        lo: [f64; 3],
        /// Highest world corner of the CT (mm).
        hi: [f64; 3],
    },
    /// Growth thresholds that do not describe an adaptive region growing.
    #[error("region growing: need step > 0, max >= start and leak growth limit > 1 (got start {start_hu} HU, max {max_hu} HU, step {step_hu} HU, leak growth limit {leak_growth_limit})")]
    BadThresholds {
        /// First upper threshold (HU).
        start_hu: f32,
        /// Highest upper threshold (HU).
        max_hu: f32,
        /// Step (HU).
        step_hu: f32,
        /// Growth factor taken as a leak.
        leak_growth_limit: f64,
    },
    /// More threshold steps than the label type holds.
    #[error("region growing: {steps} threshold steps, at most 254 are supported")]
    TooManySteps {
        /// Steps asked for.
        steps: usize,
    },
    /// The region leaked already at the first threshold.
    #[error("region growing: the region exploded already at the first threshold {start_hu} HU (seed {} not in an airway?)", ijk(.seed))]
    ExplodedAtStart {
        /// First threshold (HU).
        start_hu: f32,
        /// Seed voxel.
        seed: [usize; 3],
    },
    /// The seed is not air at any threshold.
    #[error("region growing: seed {} ({}) is above every threshold up to {max_hu} HU", ijk(.seed), if .value.is_finite() { format!("{} HU", .value) } else { "not a finite number, counted as tissue".to_string() })]
    SeedNotAir {
        /// Seed voxel.
        seed: [usize; 3],
        /// Its value (HU).
        value: f32,
        /// The highest threshold tried (HU).
        max_hu: f32,
    },
    /// No trachea found for the automatic seed.
    #[error("trachea seed: no round air region enclosed by tissue near the body centre over {min_run_mm} mm of the top {:.0}% of the slices; give --seed X,Y,Z", .search_fraction * 100.0)]
    NoTracheaSeed {
        /// Length of air run required (mm).
        min_run_mm: f64,
        /// Fraction of the slices searched, from the top.
        search_fraction: f64,
    },
    /// A non-finite iso level for marching cubes.
    #[error("marching cubes: iso level {0} is not finite")]
    BadIsoLevel(f32),
    /// A path end that is not inside the mask.
    #[error("centred path: the {what} voxel {voxel} is not inside the mask")]
    OutsideMask {
        /// "start" or "target".
        what: &'static str,
        /// Linear voxel index.
        voxel: usize,
    },
    /// Two mask voxels that no path inside the mask joins.
    #[error("centred path: voxel {target} is not connected to voxel {start} inside the mask")]
    NotConnected {
        /// Linear index of the start voxel.
        start: usize,
        /// Linear index of the target voxel.
        target: usize,
    },
    /// An empty region or mask where one is needed.
    #[error("{stage}: the {what} is empty")]
    Empty {
        /// Which operation.
        stage: &'static str,
        /// What is empty.
        what: &'static str,
    },
}
