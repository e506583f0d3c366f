//! Write the phantom CT as raw little-endian int16 HU plus a JSON header, for the
//! region-growing comparison script (bench/region_grow_vs_sitk.py).
//!
//! Usage: phantom_ct_raw OUT_PREFIX [NX NY NZ]  (default: the test-size grid)

use bronchosim::phantom::{make_ct_phantom, CtPhantomOptions};
use std::io::Write;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let prefix = args.get(1).cloned().unwrap_or_else(|| "phantom_ct".into());
    let mut opts = CtPhantomOptions::default();
    if args.len() >= 5 {
        let d = [args[2].parse()?, args[3].parse()?, args[4].parse()?];
        opts.dims = Some(d);
        // A 512x512x400 chest CT: 0.7 mm in-plane (358 mm field of view), 0.5 mm slices.
        opts.spacing_mm = [0.7, 0.7, 0.5];
    }
    let ph = make_ct_phantom(&opts)?;
    let seed = bronchosim::volume::seed::find_trachea_seed(&ph.ct, &Default::default())?;
    let data: Vec<u8> = ph
        .ct
        .data
        .iter()
        .flat_map(|&v| (v.round().clamp(-32768.0, 32767.0) as i16).to_le_bytes())
        .collect();
    std::fs::File::create(format!("{prefix}.raw"))?.write_all(&data)?;
    let a = ph.ct.affine;
    let header = serde_json::json!({
        "dims": ph.ct.dims,
        "affine": (0..4).map(|r| (0..4).map(|c| a[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "dtype": "int16",
        "truth_volume_ml": ph.truth_volume_ml,
        "branches": ph.tree.branches.len(),
        "seed_voxel": seed.voxel,
    });
    std::fs::write(
        format!("{prefix}.json"),
        serde_json::to_string_pretty(&header)?,
    )?;
    eprintln!(
        "{prefix}.raw: {:?} voxels, truth lumen {:.2} ml",
        ph.ct.dims, ph.truth_volume_ml
    );
    for b in &ph.tree.branches {
        eprintln!(
            "  branch {:2} gen {} parent {:?} len {:.1} mm  diam {:.1}..{:.1} mm",
            b.id,
            b.generation,
            b.parent,
            b.length_mm(),
            2.0 * b.radius_start_mm,
            b.min_diameter_mm()
        );
    }
    Ok(())
}
