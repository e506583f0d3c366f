#!/usr/bin/env python3
"""Undistortion of a 1280x1024 RGB f32 frame: OpenCV vs bronchosim, timed in one run.

OpenCV: cv2.initUndistortRectifyMap(K, D, I, K, size, CV_32FC1) and
cv2.remap(img, map_x, map_y, INTER_LINEAR, BORDER_CONSTANT). bronchosim:
UndistortMap::for_camera and remap_bilinear, via `examples/undistort_timing.rs` built in
release mode. A map reused for every frame is also timed both ways: OpenCV converts it once
with cv2.convertMaps (CV_16SC2, its fixed-point remap tables) and remaps into a preallocated
dst; bronchosim builds a RemapPlan once and calls remap_into. Both at the default thread
count and with one thread; each round times both sides (medians of REPS runs); printed are
the best time of ROUNDS alternating rounds and the MEDIAN over rounds of the per-round ratio
bronchosim / OpenCV (below 1 means bronchosim is faster; the machine is shared and noisy).

Both sides run as child processes with the same environment. Each repetition allocates
its outputs (10 MB of maps, 16 MB of image); with glibc's default trim threshold those pages
can go back to the kernel after every call and fault in again, which can cost more than the
arithmetic. So everything is timed twice: with glibc's defaults, and with
GLIBC_TUNABLES trim_threshold=1 GiB, mmap_threshold=32 MiB for both sides (the allocation pattern of a
long-running pipeline, where maps and frames are reused).

    bench/.venv/bin/python bench/undistort_vs_opencv.py [REPS] [ROUNDS]
(all comparisons, venv included: bash bench/run_all.sh)
"""
import json
import os
import subprocess
import sys
import time

import cv2
import numpy as np

import cargo_target

W, H = 1280, 1024
K = np.array([[800.0, 0.0, 639.5], [0.0, 800.0, 511.5], [0.0, 0.0, 1.0]])
D = np.array([-0.35, 0.12, 0.001, 0.0015, 0.0])


def median_ms(reps, f):
    f()
    t = []
    for _ in range(reps):
        s = time.perf_counter()
        f()
        t.append((time.perf_counter() - s) * 1e3)
    return float(np.median(t))


def opencv(reps, threads):
    cv2.setNumThreads(threads)
    img = ((np.arange(W * H * 3) % 251) / 250.0).astype(np.float32).reshape(H, W, 3)
    map_ms = median_ms(reps, lambda: cv2.initUndistortRectifyMap(K, D, np.eye(3), K, (W, H), cv2.CV_32FC1))
    mx, my = cv2.initUndistortRectifyMap(K, D, np.eye(3), K, (W, H), cv2.CV_32FC1)
    remap_ms = median_ms(reps, lambda: cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT))
    m1, m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
    dst = np.empty_like(img)
    reuse_ms = median_ms(reps, lambda: cv2.remap(img, m1, m2, cv2.INTER_LINEAR, dst=dst,
                                                 borderMode=cv2.BORDER_CONSTANT))
    return dict(map_ms=map_ms, remap_ms=remap_ms, reuse_ms=reuse_ms)


def child_env(threads, tunables):
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    env.pop("GLIBC_TUNABLES", None)
    if tunables:
        env["GLIBC_TUNABLES"] = tunables
    return env


def opencv_child(reps, threads, tunables):
    cmd = [sys.executable, os.path.abspath(__file__), "--opencv-worker", str(reps), str(threads)]
    out = subprocess.run(cmd, env=child_env(threads, tunables), capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def ours(exe, reps, threads, tunables):
    out = subprocess.run([exe, str(reps)], env=child_env(threads, tunables), capture_output=True, text=True,
                         check=True).stdout
    return json.loads(out)


def main():
    if sys.argv[1:2] == ["--opencv-worker"]:
        print(json.dumps(opencv(int(sys.argv[2]), int(sys.argv[3]))))
        return
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    (exe,) = cargo_target.example("undistort_timing")
    cores = os.cpu_count()
    print(f"OpenCV {cv2.__version__}, {W}x{H} RGB f32, median of {reps} reps, best of {rounds} rounds, {cores} cores")
    names = (("map_ms", "initUndistortRectifyMap"), ("remap_ms", "remap INTER_LINEAR"),
             ("total", "map + remap"), ("reuse_ms", "remap, map reused"))
    for label, tunables in (("glibc default", ""), ("no trim, mmap >32 MB", "glibc.malloc.trim_threshold=1073741824:glibc.malloc.mmap_threshold=33554432")):
        for threads in (cores, 1):
            best_cv, best_us, ratios = {}, {}, {k: [] for k, _ in names}
            for _ in range(rounds):
                cv = opencv_child(reps, threads, tunables)
                us = ours(exe, reps, threads, tunables)
                for d in (cv, us):
                    d["total"] = d["map_ms"] + d["remap_ms"]
                for k, _ in names:
                    best_cv[k] = min(best_cv.get(k, float("inf")), cv[k])
                    best_us[k] = min(best_us.get(k, float("inf")), us[k])
                    ratios[k].append(us[k] / cv[k])
            for k, name in names:
                print(f"{label:21s} threads={threads} {name:24s} OpenCV {best_cv[k]:7.2f} ms  "
                      f"bronchosim {best_us[k]:7.2f} ms  median ratio {float(np.median(ratios[k])):.2f}  "
                      f"(rounds: {' '.join(f'{r:.2f}' for r in ratios[k])})")

if __name__ == "__main__":
    main()
