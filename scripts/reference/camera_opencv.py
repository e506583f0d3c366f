#!/usr/bin/env python3
"""Reference values for src/camera against OpenCV (opencv-python-headless).

Writes tests/data/camera_opencv.json and real OpenCV FileStorage files under
tests/data/camera/. Run from the repository root:

    /work/venv/bin/python scripts/reference/camera_opencv.py

For every camera: cv2.projectPoints of 3-D points covering the field of view,
cv2.undistortPoints of distorted pixels covering the whole image (P = K: pixels; no P:
normalised), and a subsample of cv2.initUndistortRectifyMap(K, D, I, K, size, CV_32FC1).

cv2.undistortPoints' default stopping rule is 5 fixed-point iterations, which is not
converged for strong distortion near the corners (off by up to tens of pixels), so the
reference is cv2.undistortPoints with criteria (COUNT+EPS, 1000, 1e-14); the default
result is kept too ("undistort_default_px") to show the gap, and every reference
undistortion is checked by re-projecting it through cv2.projectPoints.
"""
import json
import os

import cv2
import numpy as np

OUT_JSON = "tests/data/camera_opencv.json"
OUT_DIR = "tests/data/camera"

# Strong-distortion cameras, all invertible over the whole image (no fold of the radial map).
CAMERAS = [
    dict(name="bronchoscope_320", width=320, height=320, fx=160.0, fy=160.0, cx=159.5, cy=159.5,
         k1=-0.28, k2=0.07, p1=0.0, p2=0.0, k3=0.0),
    dict(name="strong_640x480", width=640, height=480, fx=600.0, fy=600.0, cx=319.5, cy=239.5,
         k1=-0.45, k2=0.2, p1=0.002, p2=-0.003, k3=-0.05),
    dict(name="wide_1280x1024", width=1280, height=1024, fx=800.0, fy=800.0, cx=639.5, cy=511.5,
         k1=-0.35, k2=0.12, p1=0.001, p2=0.0015, k3=0.0),
    dict(name="offcentre_400x300", width=400, height=300, fx=420.0, fy=400.0, cx=210.3, cy=140.8,
         k1=-0.3, k2=0.09, p1=-0.0025, p2=0.0018, k3=-0.01),
]

CONVERGED = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-14)


def kd(c):
    K = np.array([[c["fx"], 0.0, c["cx"]], [0.0, c["fy"], c["cy"]], [0.0, 0.0, 1.0]])
    D = np.array([c["k1"], c["k2"], c["p1"], c["p2"], c["k3"]])
    return K, D


def project(pts3, K, D):
    out, _ = cv2.projectPoints(pts3.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    return out.reshape(-1, 2)


def reference(c, rng):
    K, D = kd(c)
    w, h = c["width"], c["height"]

    # Distorted pixels over the whole image: a 7x7 grid through the corners plus random ones.
    gu, gv = np.meshgrid(np.linspace(0, w - 1, 7), np.linspace(0, h - 1, 7))
    px = np.concatenate([np.stack([gu.ravel(), gv.ravel()], 1),
                         rng.uniform([0, 0], [w - 1, h - 1], size=(8, 2))])
    src = px.reshape(-1, 1, 2)
    und_px = cv2.undistortPoints(src, K, D, P=K, criteria=CONVERGED).reshape(-1, 2)
    und_norm = cv2.undistortPoints(src, K, D, criteria=CONVERGED).reshape(-1, 2)
    und_default = cv2.undistortPoints(src, K, D, P=K).reshape(-1, 2)
    # The converged inverse must re-project onto the input pixel.
    back = project(np.concatenate([und_norm, np.ones((len(px), 1))], 1), K, D)
    reproj = float(np.abs(back - px).max())
    assert reproj < 1e-6, (c["name"], reproj)

    # 3-D points covering the field of view: normalised coordinates inside the undistorted
    # image box (from the corner preimages), depths 2..80 mm.
    lo, hi = und_norm.min(0), und_norm.max(0)
    xy = rng.uniform(lo, hi, size=(50, 2))
    z = rng.uniform(2.0, 80.0, size=(50, 1))
    pts3 = np.concatenate([xy * z, z], 1)
    proj = project(pts3, K, D)

    # Undistortion map with newK = K, R = I, CV_32FC1; corners plus random pixels.
    map_x, map_y = cv2.initUndistortRectifyMap(K, D, np.eye(3), K, (w, h), cv2.CV_32FC1)
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]])
    sample = np.concatenate([corners, np.stack([rng.integers(0, w, 196), rng.integers(0, h, 196)], 1)])
    mx = map_x[sample[:, 1], sample[:, 0]].astype(float)
    my = map_y[sample[:, 1], sample[:, 0]].astype(float)

    # Field of view through the distortion: rays through the outer edges of the edge pixels.
    def ray(u, v):
        n = cv2.undistortPoints(np.array([[[u, v]]], float), K, D, criteria=CONVERGED).reshape(2)
        r = np.array([n[0], n[1], 1.0])
        return r / np.linalg.norm(r)

    def angle(a, b):
        ra, rb = ray(*a), ray(*b)
        return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(ra, rb)), ra @ rb)))

    fov = dict(horizontal=angle((-0.5, c["cy"]), (w - 0.5, c["cy"])),
               vertical=angle((c["cx"], -0.5), (c["cx"], h - 0.5)),
               diagonal=angle((-0.5, -0.5), (w - 0.5, h - 0.5)))
    # Distortion strength: largest |ideal - distorted| over every pixel centre on the border.
    bu = np.arange(w, dtype=float)
    bv = np.arange(h, dtype=float)
    border = np.concatenate([np.stack([bu, np.zeros(w)], 1), np.stack([bu, np.full(w, h - 1.0)], 1),
                             np.stack([np.zeros(h), bv], 1), np.stack([np.full(h, w - 1.0), bv], 1)])
    ideal = cv2.undistortPoints(border.reshape(-1, 1, 2), K, D, P=K, criteria=CONVERGED).reshape(-1, 2)
    strength = float(np.linalg.norm(ideal - border, axis=1).max())

    gap = float(np.abs(und_default - und_px).max())
    print(f"{c['name']}: fov {fov['horizontal']:.2f}/{fov['vertical']:.2f}/{fov['diagonal']:.2f} deg, "
          f"max distortion {strength:.2f} px; undistortPoints default vs converged max {gap:.3g} px, reprojection {reproj:.2g} px")
    return dict(
        camera=c,
        project=dict(points_mm=pts3.tolist(), pixels=proj.tolist()),
        undistort=dict(distorted_px=px.tolist(), ideal_px=und_px.tolist(), normalized=und_norm.tolist(),
                       undistort_default_px=und_default.tolist(), default_vs_converged_max_px=gap),
        fov_deg=fov,
        max_distortion_px=strength,
        map=dict(pixels=sample.tolist(), map_x=mx.tolist(), map_y=my.tolist()),
    )


def write_filestorage(c, path):
    K, D = kd(c)
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", c["width"])
    fs.write("image_height", c["height"])
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D.reshape(1, 5))
    fs.release()


def main():
    rng = np.random.default_rng(20040926)
    cams = [reference(c, rng) for c in CAMERAS]
    doc = dict(source=f"OpenCV {cv2.__version__} via scripts/reference/camera_opencv.py", cameras=cams)
    with open(OUT_JSON, "w") as f:
        json.dump(doc, f, separators=(",", ":"))
    os.makedirs(OUT_DIR, exist_ok=True)
    for c in (CAMERAS[1], CAMERAS[3]):
        write_filestorage(c, os.path.join(OUT_DIR, c["name"] + ".yml"))
        write_filestorage(c, os.path.join(OUT_DIR, c["name"] + ".xml"))
        with open(os.path.join(OUT_DIR, c["name"] + ".json"), "w") as f:
            json.dump({k: v for k, v in c.items() if k != "name"}, f, indent=1)
    print(f"wrote {OUT_JSON} ({os.path.getsize(OUT_JSON)} bytes) and {OUT_DIR}/")


if __name__ == "__main__":
    main()
