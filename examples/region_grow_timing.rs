//! Time region growing and the whole segmentation on a raw int16 CT written by
//! `phantom_ct_raw`, and report peak memory (VmHWM) against the CT's size as f32.
//!
//! Usage: region_grow_timing PREFIX UPPER_HU   (reads PREFIX.raw and PREFIX.json)

use bronchosim::math::Affine;
use bronchosim::volume::region_grow::connected_threshold;
use bronchosim::volume::segment::{segment_airway, SegmentOptions};
use bronchosim::volume::Volume;
use std::io::Read;
use std::time::Instant;

fn vm_hwm_kb() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let prefix = &args[1];
    let upper: f32 = args[2].parse()?;
    let h: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(format!("{prefix}.json"))?)?;
    let dims: Vec<usize> = h["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let seed: Vec<usize> = h["seed_voxel"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let mut affine = Affine::identity();
    for r in 0..4 {
        for c in 0..4 {
            affine[(r, c)] = h["affine"][r][c].as_f64().unwrap();
        }
    }
    // Stream the int16 file into f32 in chunks: the CT is the only large buffer.
    let n = dims[0] * dims[1] * dims[2];
    let mut data = Vec::with_capacity(n);
    let mut f = std::fs::File::open(format!("{prefix}.raw"))?;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let k = f.read(&mut buf)?;
        if k == 0 {
            break;
        }
        data.extend(
            buf[..k]
                .chunks_exact(2)
                .map(|b| i16::from_le_bytes([b[0], b[1]]) as f32),
        );
    }
    let ct = Volume::from_data([dims[0], dims[1], dims[2]], affine, data)?;
    let ct_mb = (n * 4) as f64 / 1e6;
    let t = Instant::now();
    let m = connected_threshold(&ct, [seed[0], seed[1], seed[2]], f32::MIN, upper)?;
    let grow_s = t.elapsed().as_secs_f64();
    let voxels = m.data.iter().filter(|&&v| v != 0).count();
    drop(m);
    let t = Instant::now();
    let seg = segment_airway(&ct, &SegmentOptions::default())?;
    let seg_s = t.elapsed().as_secs_f64();
    let peak_mb = vm_hwm_kb() as f64 * 1024.0 / 1e6;
    println!(
        "{{\"grow_s\": {grow_s:.4}, \"grow_voxels\": {voxels}, \"segment_s\": {seg_s:.3}, \"segment_volume_ml\": {:.2}, \"threshold_hu\": {}, \"branches\": {}, \"peak_mb\": {peak_mb:.1}, \"ct_mb\": {ct_mb:.1}}}",
        seg.volume_ml, seg.threshold_hu, seg.branch_count
    );
    Ok(())
}
