"""NIfTI load speed: bronchosim's reader against nibabel on the same 512x512x400 int16 .nii.gz.

Both are timed in this one run (the machine is shared and noisy; only the ratio means much).
Usage: bench/.venv/bin/python bench/nifti_vs_nibabel.py [--size 512,512,400] [--repeats 3]
(all comparisons, venv included: bash bench/run_all.sh)
"""
import argparse
import os
import subprocess
import tempfile
import time

import nibabel as nib
import numpy as np

import cargo_target



def ct_like(shape, seed=0):
    """A chest-CT-like int16 volume: air outside an elliptic body, lungs, tissue, noise."""
    rng = np.random.default_rng(seed)
    nx, ny, nz = shape
    x = (np.arange(nx) - nx / 2)[:, None] / (nx * 0.45)
    y = (np.arange(ny) - ny / 2)[None, :] / (ny * 0.35)
    body = (x**2 + y**2) < 1.0
    lungs = (((x - 0.45) / 0.35) ** 2 + (y / 0.7) ** 2 < 1) | (((x + 0.45) / 0.35) ** 2 + (y / 0.7) ** 2 < 1)
    slice2d = np.where(body, 40.0, -1000.0)
    slice2d = np.where(lungs, -850.0, slice2d)
    vol = np.repeat(slice2d[:, :, None], nz, axis=2)
    vol += rng.normal(0, 20, size=shape)
    return np.clip(vol, -1024, 3071).astype(np.int16)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="512,512,400")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    shape = tuple(int(v) for v in args.size.split(","))
    (exe,) = cargo_target.example("nifti_load_timing")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "ct.nii.gz")
        aff = np.diag([-0.7, -0.7, 0.8, 1.0])
        nib.save(nib.Nifti1Image(ct_like(shape), aff), path)
        mb = os.path.getsize(path) / 1e6
        nib_times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            data = nib.load(path).get_fdata(dtype=np.float32)  # HU as float32, like bronchosim
            nib_times.append((time.perf_counter() - t) * 1e3)
            del data
        out = subprocess.run([exe, path, str(args.repeats)], capture_output=True, text=True, check=True).stdout
        ours = [float(l.split()[1]) for l in out.splitlines() if l.startswith("ms")]
    best_nib, best_ours = min(nib_times), min(ours)
    print(f"volume {shape} int16, {mb:.1f} MB compressed")
    print(f"nibabel get_fdata(float32): best {best_nib:.0f} ms  (all {', '.join(f'{t:.0f}' for t in nib_times)})")
    print(f"bronchosim read_nifti:       best {best_ours:.0f} ms  (all {', '.join(f'{t:.0f}' for t in ours)})")
    print(f"ratio nibabel/bronchosim = {best_nib / best_ours:.2f}x (>1: bronchosim faster)")


if __name__ == "__main__":
    main()
