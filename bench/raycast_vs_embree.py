#!/usr/bin/env python3
"""Closest-hit throughput: embreex (Embree 4 via PyPI) against bronchosim's BVH, one run.

Same mesh (the phantom's true lumen, `bronchosim phantom` truth/lumen.ply, ~260k triangles)
and the same rays (benches/common/phantom_rays.rs, written by `examples/write_bench_mesh.rs`):
a 512x512 pinhole camera inside the trachea, and 2^20 incoherent random rays from points
inside the lumen. Ours traces the camera as packets of 4x4 pixels
(`Scene::closest_hits_image_rows`, row `camera`) and also one ray at a time
(`camera_single`); the random rays one at a time.

embreex's `EmbreeScene.run` traces the whole batch on the calling thread. The "2 threads"
figure runs two halves of the batch in two Python threads; measured here it is no faster than
one thread (embreex holds the GIL), so the 2-thread ratio compares ours against the best
embreex figure.
Ours is timed by `examples/raycast_throughput.rs` with RAYON_NUM_THREADS=1 and 2.
On a shared machine wall-clock figures swing with other load; the second table divides by
CPU seconds instead (embreex: process_time; ours: summed per-thread schedstat), 1 thread.

Usage: bench/.venv/bin/python bench/raycast_vs_embree.py [--repeats 5]
(all comparisons, venv included: bash bench/run_all.sh; trimesh and embreex are in bench/requirements.txt)
"""

import argparse
import json
import os
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import trimesh
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

import cargo_target

ROOT = Path(__file__).resolve().parent.parent


def cargo_example(name, args, env=None):
    (exe,) = cargo_target.example(name)
    out = subprocess.run(
        [str(exe), *args], cwd=ROOT, check=True, capture_output=True, text=True,
        env={**os.environ, **(env or {})},
    )
    return out.stdout.strip()


def load_rays(path):
    r = np.fromfile(path, dtype="<f4").reshape(-1, 6)
    return np.ascontiguousarray(r[:, :3]), np.ascontiguousarray(r[:, 3:])


def embree_trace(scene, o, d, threads):
    if threads == 1:
        return scene.run(o, d, output=1)
    parts = np.array_split(np.arange(len(o)), threads)
    res = [None] * threads

    def work(k):
        idx = parts[k]
        res[k] = scene.run(o[idx], d[idx], output=1)

    ts = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    return {"primID": np.concatenate([r["primID"] for r in res])}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        mesh_path = cargo_example("write_bench_mesh", [tmp])
        mesh = trimesh.load(mesh_path, process=False)
        tris = mesh.vertices[mesh.faces].astype(np.float32)
        t0 = time.perf_counter()
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, tris)
        # Embree builds lazily on the first query: include one tiny query in the build time.
        scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=1)
        embree_build = time.perf_counter() - t0

        ours = {}
        for threads in (1, 2):
            line = cargo_example(
                "raycast_throughput", [tmp, str(args.repeats)], {"RAYON_NUM_THREADS": str(threads)}
            )
            ours[threads] = json.loads(line)

        print(f"mesh: {len(tris)} triangles; embree build {embree_build:.3f} s, "
              f"ours {ours[1]['build_s']:.3f} s (1 thread) / {ours[2]['build_s']:.3f} s (2 threads)")
        print(f"{'rays':13} {'embree 1t':>10} {'embree 2t':>10} {'ours 1t':>10} {'ours 2t':>10}"
              f" {'1t ratio':>9} {'2t ratio':>9}  hits agree")
        cpu_rows = []
        embree_runs = {}
        for name in ("camera", "camera_single", "random"):
            rays = name.split("_")[0]
            if rays not in embree_runs:
                o, d = load_rays(os.path.join(tmp, f"rays_{rays}.bin"))
                emb, emb_cpu = {}, {}
                for threads in (1, 2):
                    best, best_cpu = float("inf"), float("inf")
                    for _ in range(args.repeats):
                        t, c = time.perf_counter(), time.process_time()
                        r = embree_trace(scene, o, d, threads)
                        best = min(best, time.perf_counter() - t)
                        best_cpu = min(best_cpu, time.process_time() - c)
                    emb[threads] = len(o) / best / 1e6
                    emb_cpu[threads] = len(o) / best_cpu / 1e6
                embree_runs[rays] = (emb, emb_cpu, r)
            emb, emb_cpu, r = embree_runs[rays]
            ids = np.asarray(r["primID"])
            mine = np.fromfile(os.path.join(tmp, f"ours_{rays}.bin"), dtype="<i4")
            agree = np.mean(ids == mine)
            o1, o2 = ours[1][f"{name}_mrays"], ours[2][f"{name}_mrays"]
            print(f"{name:13} {emb[1]:10.3f} {emb[2]:10.3f} {o1:10.3f} {o2:10.3f}"
                  f" {o1 / emb[1]:9.2f} {o2 / max(emb[1], emb[2]):9.2f}  {agree:.4%}")
            c_ours = ours[1][f"{name}_mrays_per_cpu_s"]
            cpu_rows.append(f"{name:13} {emb_cpu[1]:10.3f} {c_ours:10.3f} {c_ours / emb_cpu[1]:9.2f}")
        print("Mrays/s wall clock, best of", args.repeats,
              "; 2t ratio = ours 2 threads / best embree figure")
        print("\nper CPU-second, 1 thread (insensitive to other load on the machine):")
        print(f"{'rays':13} {'embree':>10} {'ours':>10} {'ratio':>9}")
        for row in cpu_rows:
            print(row)


if __name__ == "__main__":
    main()
