"""Marching cubes on a 512x512x400 CT-like volume: bronchosim vs vtkFlyingEdges3D vs skimage.

One run: generates (or reuses) the volume as raw float32 (x fastest) under --dir, times
VTK's vtkFlyingEdges3D, skimage.measure.marching_cubes(method='lorensen') and bronchosim's
marching cubes (release example `mc_timing`, best of 3 in-process runs), and prints ratios and
bronchosim's peak memory relative to the volume's size.
Run: bench/.venv/bin/python bench/marching_cubes_vs_vtk.py [--dir /tmp/bronchosim_bench]
(all comparisons, venv included: bash bench/run_all.sh)
"""
import argparse
import json
import os
import pathlib
import subprocess
import time

import numpy as np

import cargo_target

NX, NY, NZ = 512, 512, 400
SPACING = (0.7, 0.7, 0.8)  # mm, x y z
ISO = -500.0


def tree_segments():
    """A branching airway: (start, end, radius) capsules in mm, 5 generations."""
    rng = np.random.default_rng(7)
    ext = np.array([NX * SPACING[0], NY * SPACING[1], NZ * SPACING[2]])
    segs = []
    start = np.array([ext[0] / 2, ext[1] / 2, ext[2] - 5.0])
    direction = np.array([0.0, 0.0, -1.0])

    def grow(p, d, length, radius, gen):
        end = p + d * length
        end = np.clip(end, 3.0, ext - 3.0)
        segs.append((p, end, radius))
        if gen == 5:
            return
        # Two children rotated away from the parent's axis in a random plane.
        side = np.cross(d, rng.normal(size=3))
        side /= np.linalg.norm(side)
        for sgn in (1, -1):
            ang = np.radians(rng.uniform(25, 45))
            child = np.cos(ang) * d + sgn * np.sin(ang) * side
            child /= np.linalg.norm(child)
            grow(end, child, length * 0.75, radius * 0.72, gen + 1)

    grow(start, direction, 110.0, 9.0, 0)
    return segs


def make_volume(path):
    segs = tree_segments()
    vol = np.empty((NZ, NY, NX), np.float32)
    rng = np.random.default_rng(11)
    ys, xs = np.meshgrid(np.arange(NY) * SPACING[1], np.arange(NX) * SPACING[0], indexing="ij")
    for z in range(NZ):
        pz = z * SPACING[2]
        sdf = np.full((NY, NX), 50.0, np.float32)
        for a, b, r in segs:
            lo, hi = np.minimum(a, b) - r - 3, np.maximum(a, b) + r + 3
            if not (lo[2] <= pz <= hi[2]):
                continue
            i0, i1 = int(max(lo[0] / SPACING[0], 0)), int(min(hi[0] / SPACING[0] + 1, NX))
            j0, j1 = int(max(lo[1] / SPACING[1], 0)), int(min(hi[1] / SPACING[1] + 1, NY))
            if i0 >= i1 or j0 >= j1:
                continue
            px, py = xs[j0:j1, i0:i1], ys[j0:j1, i0:i1]
            ab = b - a
            t = ((px - a[0]) * ab[0] + (py - a[1]) * ab[1] + (pz - a[2]) * ab[2]) / ab.dot(ab)
            t = np.clip(t, 0, 1)
            d = np.sqrt((px - a[0] - t * ab[0]) ** 2 + (py - a[1] - t * ab[1]) ** 2 + (pz - a[2] - t * ab[2]) ** 2) - r
            sdf[j0:j1, i0:i1] = np.minimum(sdf[j0:j1, i0:i1], d)
        # Air -1000, wall +40, ~0.6 mm partial-volume blur, 20 HU noise.
        vol[z] = -480.0 + 520.0 * np.tanh(sdf / 0.6) + rng.normal(0, 20, (NY, NX)).astype(np.float32)
    vol.tofile(path)
    return vol


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dir", default="/tmp/bronchosim_bench")
    args = ap.parse_args()
    d = pathlib.Path(args.dir)
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"mc_ct_{NX}x{NY}x{NZ}.f32"
    if path.exists() and path.stat().st_size == 4 * NX * NY * NZ:
        vol = np.fromfile(path, np.float32).reshape(NZ, NY, NX)
    else:
        t = time.perf_counter()
        vol = make_volume(path)
        print(f"generated {path} in {time.perf_counter() - t:.1f} s")
    print(f"volume {NX}x{NY}x{NZ} float32 = {vol.nbytes / 1e6:.0f} MB, iso {ISO}, cpus {os.cpu_count()}")

    # bronchosim (release build of the example; built before timing).
    (exe,) = cargo_target.example("mc_timing")
    cmd = ["/usr/bin/time", "-v", str(exe), str(path), str(NX), str(NY), str(NZ), *map(str, SPACING), str(ISO), "3"]
    p = subprocess.run(cmd, capture_output=True, text=True, check=True)
    ours = json.loads(p.stdout.strip().splitlines()[-1])
    max_rss = [l for l in p.stderr.splitlines() if "Maximum resident set size" in l]
    print(f"bronchosim: best {ours['best_s']:.3f} s of {['%.3f' % t for t in ours['times_s']]}, "
          f"{ours['triangles']} triangles, {ours['vertices']} vertices, threads {ours['threads']}, "
          f"boundary edges {ours['boundary_edges']}, non-manifold {ours['non_manifold_edges']}")
    print(f"bronchosim peak memory: VmHWM {ours['vm_hwm_bytes'] / 1e6:.0f} MB = "
          f"{ours['vm_hwm_bytes'] / ours['volume_bytes']:.2f} x the volume; {max_rss[0].strip() if max_rss else ''}")

    # The same on one thread, for a per-core comparison with single-threaded VTK / skimage.
    p1 = subprocess.run(cmd[2:], capture_output=True, text=True, check=True, env={**os.environ, "RAYON_NUM_THREADS": "1"})
    ours1 = json.loads(p1.stdout.strip().splitlines()[-1])
    print(f"bronchosim, 1 thread: best {ours1['best_s']:.3f} s of {['%.3f' % t for t in ours1['times_s']]}")

    # VTK flying edges.
    import vtk
    from vtk.util import numpy_support

    smp = vtk.vtkSMPTools()
    backend = smp.GetBackend()
    img = vtk.vtkImageData()
    img.SetDimensions(NX, NY, NZ)
    img.SetSpacing(*SPACING)
    arr = numpy_support.numpy_to_vtk(vol.ravel(), deep=False)
    img.GetPointData().SetScalars(arr)
    vtk_times = []
    for _ in range(3):
        fe = vtk.vtkFlyingEdges3D()
        fe.SetInputData(img)
        fe.SetValue(0, ISO)
        fe.ComputeNormalsOff()
        fe.ComputeGradientsOff()
        fe.ComputeScalarsOff()
        t = time.perf_counter()
        fe.Update()
        vtk_times.append(time.perf_counter() - t)
        vtk_tris = fe.GetOutput().GetNumberOfCells()
    vtk_best = min(vtk_times)
    print(f"vtkFlyingEdges3D (VTK {vtk.vtkVersion.GetVTKVersion()}, SMP backend {backend}, "
          f"{smp.GetEstimatedNumberOfThreads()} threads): best {vtk_best:.3f} s of "
          f"{['%.3f' % t for t in vtk_times]}, {vtk_tris} triangles")

    # skimage (single-threaded), one timed run.
    from skimage.measure import marching_cubes
    t = time.perf_counter()
    verts, faces, _, _ = marching_cubes(vol, ISO, spacing=SPACING[::-1], method="lorensen")
    sk = time.perf_counter() - t
    print(f"skimage marching_cubes(lorensen): {sk:.3f} s, {len(faces)} triangles")

    print(f"ratio vtkFlyingEdges3D / bronchosim = {vtk_best / ours['best_s']:.2f} (aim >= 1)")
    print(f"ratio skimage / bronchosim = {sk / ours['best_s']:.2f} (aim >= 4)")
    print(f"ratio vtkFlyingEdges3D / bronchosim 1 thread = {vtk_best / ours1['best_s']:.2f}, "
          f"skimage / bronchosim 1 thread = {sk / ours1['best_s']:.2f}")
    print(f"triangles: bronchosim {ours['triangles']}, skimage {len(faces)}, vtk {vtk_tris}")


if __name__ == "__main__":
    main()
