"""Region growing: SimpleITK ConnectedThreshold vs bronchosim on a 512x512x400 phantom CT.

One run: builds the examples in release, writes the phantom (raw int16 + JSON header) unless
present, times SimpleITK (6-connected, same seed and threshold) and ours in the same run,
checks both masks have the same voxel count, and prints the ratio and our peak memory.

Usage: bench/.venv/bin/python bench/region_grow_vs_sitk.py [WORKDIR]  (default /tmp/bronchosim_bench)
(all comparisons, venv included: bash bench/run_all.sh)
"""
import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np
import SimpleITK as sitk

import cargo_target

work = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/bronchosim_bench")
work.mkdir(parents=True, exist_ok=True)
prefix = work / "phantom_512"
upper = -500
phantom_ct_raw, region_grow_timing = cargo_target.example("phantom_ct_raw", "region_grow_timing")
if not (prefix.with_suffix(".raw")).exists():
    subprocess.run([phantom_ct_raw, prefix, "512", "512", "400"], check=True)
h = json.loads(prefix.with_suffix(".json").read_text())
nx, ny, nz = h["dims"]
arr = np.fromfile(prefix.with_suffix(".raw"), dtype="<i2").reshape(nz, ny, nx)
img = sitk.GetImageFromArray(arr.astype(np.float32))
seed = tuple(int(v) for v in h["seed_voxel"])
f = sitk.ConnectedThresholdImageFilter()
f.SetLower(-1e30)
f.SetUpper(upper)
f.SetSeedList([seed])
f.SetReplaceValue(1)
times = []
for _ in range(3):
    t = time.perf_counter()
    out = f.Execute(img)
    times.append(time.perf_counter() - t)
sitk_s = min(times)
sitk_voxels = int(sitk.GetArrayViewFromImage(out).sum())
ours = [json.loads(subprocess.run([region_grow_timing, prefix, str(upper)], check=True, capture_output=True, text=True).stdout) for _ in range(3)]
best = min(ours, key=lambda o: o["grow_s"])
print(f"grid {nx}x{ny}x{nz}, seed {seed}, upper {upper} HU, threads {os.cpu_count()}")
print(f"SimpleITK ConnectedThreshold: {sitk_s:.3f} s  ({sitk_voxels} voxels)")
print(f"bronchosim connected_threshold: {best['grow_s']:.3f} s  ({best['grow_voxels']} voxels)")
print(f"ratio SimpleITK / bronchosim: {sitk_s / best['grow_s']:.1f}x")
print(f"bronchosim segment_airway (seed search, adaptive threshold, morphology, branches): {best['segment_s']:.2f} s, "
      f"{best['segment_volume_ml']} ml, threshold {best['threshold_hu']} HU, {best['branches']} branches")
print(f"peak memory {best['peak_mb']:.0f} MB = {best['peak_mb'] / best['ct_mb']:.2f} x the CT as f32 ({best['ct_mb']:.0f} MB)")
assert sitk_voxels == best["grow_voxels"], "masks differ in size"
