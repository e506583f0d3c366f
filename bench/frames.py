#!/usr/bin/env python3
"""Frame input speed: bronchosim (criterion bench `frames`) vs OpenCV on the same files.

Makes the inputs (320x320 8- and 16-bit PNG, a 300-frame 320x320 H.264 mp4), times OpenCV
decoding them to linear float32 RGB (the same work bronchosim does: decode + sRGB->linear
LUT), then runs `cargo bench --bench frames` on the same files and prints ours / OpenCV.
Run: bench/.venv/bin/python bench/frames.py (all comparisons, venv included: bash bench/run_all.sh)
"""
import os
import re
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np

import cargo_target

W = H = 320
N_VIDEO = 300


def srgb_to_linear(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


LUT8 = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
LUT16 = srgb_to_linear(np.arange(65536) / 65535.0).astype(np.float32)


def test_frame(seed):
    """The same smooth frame as benches/frames.rs (linear RGB, H x W x 3)."""
    u = (np.arange(W) / W)[None, :].astype(np.float32)
    v = (np.arange(H) / H)[:, None].astype(np.float32)
    s = seed * 0.1
    r = 0.5 + 0.4 * np.sin(9 * u + s) * np.cos(7 * v)
    g = 0.3 + 0.2 * np.sin(13 * v + s) + 0 * u
    b = 0.2 + 0.15 * np.cos(5 * (u + v) + s)
    return np.stack([r, g, b], axis=-1)


def best(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main():
    tmp = tempfile.mkdtemp(prefix="bronchosim-bench-frames-")
    f0 = linear_to_srgb(test_frame(0))
    cv2.imwrite(f"{tmp}/frame8.png", np.round(f0 * 255).astype(np.uint8)[..., ::-1])
    cv2.imwrite(f"{tmp}/frame16.png", np.round(f0 * 65535).astype(np.uint16)[..., ::-1])
    for i in range(N_VIDEO):
        img = np.round(linear_to_srgb(test_frame(i)) * 255).astype(np.uint8)[..., ::-1]
        cv2.imwrite(f"{tmp}/v{i:03d}.png", img)
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", "v%03d.png", "-c:v", "libx264",
                    "-crf", "18", "-pix_fmt", "yuv420p", "video.mp4"], cwd=tmp, check=True)

    def read8():
        return LUT8[cv2.imread(f"{tmp}/frame8.png", cv2.IMREAD_UNCHANGED)[..., ::-1]]

    def read16():
        return LUT16[cv2.imread(f"{tmp}/frame16.png", cv2.IMREAD_UNCHANGED)[..., ::-1]]

    lin = test_frame(0).astype(np.float32)

    def write8():
        cv2.imwrite(f"{tmp}/w8.png", np.round(linear_to_srgb(lin) * 255).astype(np.uint8)[..., ::-1])

    def write16():
        cv2.imwrite(f"{tmp}/w16.png", np.round(linear_to_srgb(lin) * 65535).astype(np.uint16)[..., ::-1])

    def video():
        cap = cv2.VideoCapture(f"{tmp}/video.mp4")
        n = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            LUT8[frame[..., ::-1]]
            n += 1
        assert n == N_VIDEO, n

    def video_open():
        cap = cv2.VideoCapture(f"{tmp}/video.mp4")
        ok, frame = cap.read()
        assert ok
        LUT8[frame[..., ::-1]]

    ref = {
        "png_read_8bit_320": best(read8, 50),
        "png_read_16bit_320": best(read16, 50),
        "png_write_8bit_320": best(write8, 30),
        "png_write_16bit_320": best(write16, 30),
        "video/video_decode_300x320": best(video, 5),
        "video/video_open_first_frame": best(video_open, 10),
    }
    env = dict(os.environ, BRONCHOSIM_BENCH_DIR=tmp)
    out = subprocess.run(["cargo", "bench", "--bench", "frames", "--", "--noplot"],
                         env=env, capture_output=True, text=True, cwd=cargo_target.ROOT)
    if out.returncode != 0:
        sys.exit(out.stderr[-3000:])
    units = {"ns": 1e-9, "µs": 1e-6, "us": 1e-6, "ms": 1e-3, "s": 1.0}
    ours = {}
    name = None
    for line in out.stdout.splitlines():
        m = re.match(r"^(\S+)\s*(time:.*)?$", line.strip())
        if m and not line.startswith(" ") and "time:" not in line.split()[0]:
            name = m.group(1)
        t = re.search(r"time:\s+\[\S+ \S+ (\S+) (\S+)", line)
        if t and name:
            ours[name] = float(t.group(1)) * units[t.group(2)]
    print(f"{'benchmark':28s} {'OpenCV':>10s} {'bronchosim':>11s} {'ours/OpenCV':>12s}")
    for k, r in ref.items():
        o = ours.get(k)
        o_s = f"{o * 1e3:9.2f}ms" if o else "   missing"
        ratio = f"{o / r:11.2f}x" if o else ""
        print(f"{k:28s} {r * 1e3:8.2f}ms {o_s:>11s} {ratio:>12s}")
    # Per decoded frame once the stream runs: (all frames - open and first) / (frames - 1).
    k_all, k_open = "video/video_decode_300x320", "video/video_open_first_frame"
    if k_all in ours and k_open in ours:
        r = (ref[k_all] - ref[k_open]) / (N_VIDEO - 1)
        o = (ours[k_all] - ours[k_open]) / (N_VIDEO - 1)
        print(f"{'video per frame (streaming)':28s} {r * 1e3:8.2f}ms {o * 1e3:9.2f}ms {o / r:11.2f}x")


if __name__ == "__main__":
    main()
