#!/usr/bin/env python3
"""How much pose error new views can take (issue 16): build a phantom case's model from its true
poses perturbed in known ways (`build --poses fixed`) and score the 8 truth views.

    python3 bench/pose_sensitivity.py CASE WORK [--bronchosim target/release/bronchosim]

CASE is a phantom case (`bronchosim phantom --out CASE`, with CASE/truth/poses.json). Each row is
a copy of CASE (files symlinked) whose poses.json holds the true poses with: independent
per-frame errors (RMS of the norm 0.05 mm / 0.1 deg, 0.1 / 0.2, 0.2 / 0.4), a common roll of
0.8 deg about each camera's optical axis, or a common shift of 0.15 mm along it.
Needs numpy and scipy.
"""
import argparse, json, os, subprocess
import numpy as np
from scipy.spatial.transform import Rotation


def perturbed(m, t_cam, rotvec_deg):
    """Camera-to-world `m` moved by `t_cam` (mm, camera axes) and turned by `rotvec_deg`."""
    a = m.copy()
    a[:3, :3] = m[:3, :3] @ Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    a[:3, 3] = m[:3, 3] + m[:3, :3] @ t_cam
    return a


def write_case(src, dst, mats):
    os.makedirs(dst, exist_ok=True)
    for n in os.listdir(src):
        if n not in ("poses.json", "truth") and not os.path.exists(f"{dst}/{n}"):
            os.symlink(os.path.abspath(f"{src}/{n}"), f"{dst}/{n}")
    d = json.load(open(f"{src}/poses.json"))
    for f, m in zip(d["frames"], mats):
        f["camera_to_world"] = [float(x) for x in m.flatten()]
    json.dump(d, open(f"{dst}/poses.json", "w"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("case")
    ap.add_argument("work")
    ap.add_argument("--bronchosim", default="target/release/bronchosim")
    args = ap.parse_args()
    truth = [np.array(f["camera_to_world"]).reshape(4, 4)
             for f in json.load(open(f"{args.case}/truth/poses.json"))["frames"]]
    rng = np.random.default_rng(3)
    rows = [("true poses", lambda m: m)]
    for t, r in [(0.05, 0.1), (0.1, 0.2), (0.2, 0.4)]:
        rows.append((f"independent {t} mm / {r} deg RMS",
                     lambda m, t=t, r=r: perturbed(m, rng.normal(0, t / 3**0.5, 3),
                                                   rng.normal(0, r / 3**0.5, 3))))
    rows.append(("common roll 0.8 deg", lambda m: perturbed(m, np.zeros(3), [0, 0, 0.8])))
    rows.append(("common shift 0.15 mm along the view", lambda m: perturbed(m, [0, 0, 0.15], np.zeros(3))))
    print("| poses | new views (dB) |\n|---|---|")
    for i, (name, f) in enumerate(rows):
        case, model = f"{args.work}/case_{i}", f"{args.work}/model_{i}"
        write_case(args.case, case, [f(m) for m in truth])
        subprocess.run([args.bronchosim, "build", case, "--out", model, "--truth",
                        f"{args.case}/truth", "--poses", "fixed", "--quiet", "--force"], check=True)
        psnr = json.load(open(f"{model}/evaluation.json"))[0]["mean_psnr_db"]
        print(f"| {name} | {psnr:.2f} |", flush=True)


if __name__ == "__main__":
    main()
