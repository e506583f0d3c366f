"""How the registration's smoothing prior should model each frame's noise (issue 16).

Reads one round's per-frame measurements written by the register_rounds example
(`cargo run --release --example register_rounds -- CASE W kinds=G final=no` writes
W/round_1/measurements.json: the pose each frame started from, its own refined pose, its status
and its Gauss-Newton information) and the phantom's true poses, and smooths the measured
corrections in several ways with the same drift + jitter prior as src/registration/prior.rs
(dense solve; 80 frames are 480 unknowns):

- `full`: each frame's information divided by a deflation factor (MeasurementNoise::Information),
- `diag`: its diagonal only, `unit-trace`: its shape with one size for all frames,
  `mean`: the video's mean information for every frame.

    python3 bench/registration_smoothing.py CASE W/round_1 [deflation ...]

Prints the median error, frames within 1 mm and 1 deg, and the RMS error per true camera axis
(x, y, z mm; pitch, yaw, roll deg) of the start, the frames' own poses and each smoothing.
"""
import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation as Rot


def load_poses(path):
    d = json.load(open(path))
    return [np.array(f["camera_to_world"]).reshape(4, 4) for f in d["frames"]]


def mat(v):
    # nalgebra matrices serialise column-major.
    return np.array(v).reshape(4, 4, order="F")


def delta(a, b):
    """World correction taking pose a to b: centre shift, rotation vector (as PoseDelta)."""
    return np.concatenate([b[:3, 3] - a[:3, 3], Rot.from_matrix(b[:3, :3] @ a[:3, :3].T).as_rotvec()])


def apply(a, d):
    m = np.eye(4)
    m[:3, :3] = Rot.from_rotvec(d[3:]).as_matrix() @ a[:3, :3]
    m[:3, 3] = a[:3, 3] + d[:3]
    return m


def axes_err(est, tru):
    rt = tru[:3, :3].T
    t = rt @ (est[:3, 3] - tru[:3, 3])
    w = np.degrees(Rot.from_matrix(rt @ est[:3, :3]).as_rotvec())
    return np.concatenate([t, w])


def block(r):
    b = np.zeros((6, 6))
    b[:3, :3] = r
    b[3:, 3:] = r
    return b


def report(name, poses, truth):
    e = np.array([axes_err(a, b) for a, b in zip(poses, truth)])
    mm = np.linalg.norm(e[:, :3], axis=1)
    dg = np.linalg.norm(e[:, 3:], axis=1)
    within = ((mm <= 1) & (dg <= 1)).sum()
    rms = np.sqrt((e**2).mean(0))
    print(f"{name:<24} median {np.median(mm):.3f} mm {np.median(dg):.3f} deg, within {within:2d}/{len(poses)}, "
          f"RMS x/y/z {rms[0]:.3f}/{rms[1]:.3f}/{rms[2]:.3f} mm, pitch/yaw/roll {rms[3]:.3f}/{rms[4]:.3f}/{rms[5]:.3f} deg")


def smooth(m, covs, usable, drift_mm=0.1, drift_deg=0.1, jitter_mm=0.3, jitter_deg=0.3):
    """Random-walk drift + jitter (DriftPrior's defaults); covs: per-frame world covariance."""
    n = len(m)
    sj = np.diag([(jitter_mm / np.sqrt(3)) ** 2] * 3 + [(np.radians(jitter_deg) / np.sqrt(3)) ** 2] * 3)
    p = np.diag([1 / (drift_mm / np.sqrt(3)) ** 2] * 3 + [1 / (np.radians(drift_deg) / np.sqrt(3)) ** 2] * 3)
    a = np.zeros((6 * n, 6 * n))
    b = np.zeros(6 * n)
    infos = []
    for f in range(n):
        i = np.linalg.inv(sj + covs[f]) if usable[f] else np.zeros((6, 6))
        infos.append(i)
        s = slice(6 * f, 6 * f + 6)
        a[s, s] += i
        b[s] += i @ m[f]
        if f > 0:
            t = slice(6 * f - 6, 6 * f)
            a[s, s] += p
            a[t, t] += p
            a[s, t] -= p
            a[t, s] -= p
    d = np.linalg.solve(a, b).reshape(n, 6)
    return np.array([d[f] + sj @ infos[f] @ (m[f] - d[f]) for f in range(n)])


def main():
    case, run = sys.argv[1], sys.argv[2]
    deflations = [float(x) for x in sys.argv[3:]] or [50.0, 200.0, 500.0]
    truth = load_poses(f"{case}/truth/poses.json")
    rows = json.load(open(f"{run}/measurements.json"))
    start = [mat(r["start"]) for r in rows]
    measured = [mat(r["measured"]) for r in rows]
    usable = np.array([r["status"] in ("converged", "not_converged") for r in rows])
    m = np.array([delta(s, x) for s, x in zip(start, measured)])
    info = [np.array(r["information"]) for r in rows]
    report("start", start, truth)
    report("frames' own", measured, truth)
    trace = np.median([np.trace(i) for i in info])
    mean = np.mean([i for i, u in zip(info, usable) if u], axis=0)
    variants = {
        "full": info,
        "diag": [np.diag(np.diag(i)) for i in info],
        "unit-trace": [i / np.trace(i) * trace for i in info],
        "mean": [mean for _ in info],
    }
    for name, ii in variants.items():
        for k in deflations:
            covs = [block(x[:3, :3]) @ np.linalg.inv(i + 1e-9 * np.trace(i) * np.eye(6)) @ block(x[:3, :3]).T * k
                    for x, i in zip(measured, ii)]
            sm = smooth(m, covs, usable)
            report(f"{name} / {k:g}", [apply(s, d) for s, d in zip(start, sm)], truth)


if __name__ == "__main__":
    main()
