#!/usr/bin/env python3
"""Undistortion of a 1280x1024 RGB f32 frame: OpenCV vs bronchosim, timed in one run.

OpenCV: cv2.initUndistortRectifyMap(K, D, I, K, size, CV_32FC1) and
cv2.remap(img, map_x, map_y, INTER_LINEAR, BORDER_CONSTANT). bronchosim:
UndistortMap::for_camera and remap_bilinear, via `examples/undistort_timing.rs` built in
release mode. Both at the default thread count and with one thread; medians of REPS runs,
best of ROUNDS alternating rounds (the machine is shared). Ratio = bronchosim / OpenCV time
(below 1 means bronchosim is faster).

    /work/venv/bin/python bench/undistort_vs_opencv.py [REPS] [ROUNDS]
"""
import json
import os
import subprocess
import sys
import time

import cv2
import numpy as np

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
    return dict(map_ms=map_ms, remap_ms=remap_ms)


def ours(exe, reps, threads):
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    out = subprocess.run([exe, str(reps)], env=env, capture_output=True, text=True, check=True).stdout
    return json.loads(out)


def main():
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "undistort_timing"], cwd=root, check=True)
    meta = json.loads(subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=root,
                                     capture_output=True, text=True, check=True).stdout)
    exe = os.path.join(meta["target_directory"], "release", "examples", "undistort_timing")
    cores = os.cpu_count()
    print(f"OpenCV {cv2.__version__}, {W}x{H} RGB f32, {reps} reps x best of {rounds} rounds, {cores} cores")
    for threads in (cores, 1):
        best_cv = dict(map_ms=float("inf"), remap_ms=float("inf"))
        best_us = dict(best_cv)
        for _ in range(rounds):
            cv = opencv(reps, threads)
            us = ours(exe, reps, threads)
            for k in best_cv:
                best_cv[k] = min(best_cv[k], cv[k])
                best_us[k] = min(best_us[k], us[k])
        for k, name in (("map_ms", "initUndistortRectifyMap"), ("remap_ms", "remap INTER_LINEAR")):
            print(f"threads={threads} {name:24s} OpenCV {best_cv[k]:8.3f} ms  bronchosim {best_us[k]:8.3f} ms  "
                  f"ratio {best_us[k] / best_cv[k]:.2f}")
        total_cv = best_cv["map_ms"] + best_cv["remap_ms"]
        total_us = best_us["map_ms"] + best_us["remap_ms"]
        print(f"threads={threads} {'map + remap':24s} OpenCV {total_cv:8.3f} ms  bronchosim {total_us:8.3f} ms  "
              f"ratio {total_us / total_cv:.2f}")


if __name__ == "__main__":
    main()
