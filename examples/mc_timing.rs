//! Time marching cubes on a raw float32 volume (x fastest), for bench/marching_cubes_vs_vtk.py.
//!
//! Usage: mc_timing FILE NX NY NZ SX SY SZ ISO [RUNS] [pipeline]
//! With `pipeline`, also runs Taubin smoothing and decimation and prints their report.
//! Prints one JSON line: best and all run times (s), triangles, vertices, boundary and
//! non-manifold edges, peak resident memory (VmHWM, bytes) and the volume's size in memory.

use std::io::Read;
use std::time::Instant;

use bronchosim::math::Affine;
use bronchosim::mesh::decimate::{decimate, DecimateOptions};
use bronchosim::mesh::metrics::{deviation, mesh_stats};
use bronchosim::mesh::smooth::{taubin, TaubinOptions};
use bronchosim::volume::{marching_cubes, Volume};

fn vm_hwm_bytes() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 9 {
        return Err("usage: mc_timing FILE NX NY NZ SX SY SZ ISO [RUNS]".into());
    }
    let dims = [a[2].parse()?, a[3].parse()?, a[4].parse()?];
    let sp: [f64; 3] = [a[5].parse()?, a[6].parse()?, a[7].parse()?];
    let iso: f32 = a[8].parse()?;
    let runs: usize = a.get(9).map_or(Ok(3), |s| s.parse())?;
    // Read in 1 MiB chunks so the peak memory is the volume, not the volume twice.
    let mut f = std::fs::File::open(&a[1]).map_err(|e| format!("{}: {e}", a[1]))?;
    let n: usize = dims.iter().product();
    let mut data: Vec<f32> = Vec::with_capacity(n);
    let mut buf = vec![0u8; 1 << 20];
    while data.len() < n {
        let want = ((n - data.len()) * 4).min(buf.len());
        f.read_exact(&mut buf[..want])
            .map_err(|e| format!("{}: {e}", a[1]))?;
        data.extend(
            buf[..want]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
        );
    }
    let mut aff = Affine::identity();
    for k in 0..3 {
        aff[(k, k)] = sp[k];
    }
    let vol = Volume::from_data(dims, aff, data)?;
    let mut times = Vec::new();
    let mut mesh = None;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        let m = marching_cubes(&vol, iso, None)?;
        times.push(t.elapsed().as_secs_f64());
        mesh = Some(m);
    }
    let mesh = mesh.unwrap();
    let s = mesh_stats(&mesh);
    let best = times.iter().cloned().fold(f64::INFINITY, f64::min);
    println!(
        "{{\"best_s\":{best},\"times_s\":{times:?},\"triangles\":{},\"vertices\":{},\"boundary_edges\":{},\
         \"non_manifold_edges\":{},\"vm_hwm_bytes\":{},\"volume_bytes\":{},\"threads\":{}}}",
        s.triangles,
        s.vertices,
        s.boundary_edges,
        s.non_manifold_edges,
        vm_hwm_bytes(),
        4 * vol.len(),
        rayon::current_num_threads()
    );
    if a.get(10).map(String::as_str) == Some("pipeline") {
        let mut sm = mesh.clone();
        let t = Instant::now();
        taubin(&mut sm, &TaubinOptions::default())?;
        let t_smooth = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (dec, rep) = decimate(&sm, &DecimateOptions::default())?;
        let t_dec = t.elapsed().as_secs_f64();
        let dev_s = deviation(&sm, &mesh);
        let dev_d = deviation(&sm, &dec);
        let sd = mesh_stats(&dec);
        println!(
            "{{\"taubin_s\":{t_smooth},\"decimate_s\":{t_dec},\"smoothing_deviation\":{},\"decimation_deviation\":{},\
             \"decimation\":{},\"decimated\":{}}}",
            serde_json::to_string(&dev_s)?,
            serde_json::to_string(&dev_d)?,
            serde_json::to_string(&rep)?,
            serde_json::to_string(&sd)?
        );
    }
    Ok(())
}
