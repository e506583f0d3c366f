"""Pose errors per camera axis: how far the poses in a poses.json are from a case's truth.

    python3 bench/pose_errors.py POSES.json TRUTH_POSES.json

For each frame the error of the estimated pose in the true camera's axes: the centre's offset
(x right, y down, z along the view, mm) and the rotation vector of R_true^T R_est (pitch about
x, yaw about y, roll about z, degrees), as `registration::pose_error_axes`. Prints the median
centre and rotation errors, the frames within 1 mm and 1 deg, and the mean and RMS per axis: a
mean near the RMS is an error the frames share (the whole video off the same way), which held
out frames cannot show and new views pay for.
"""
import json
import sys

import numpy as np
from scipy.spatial.transform import Rotation as Rot


def load_poses(path):
    d = json.load(open(path))
    return [np.array(f["camera_to_world"]).reshape(4, 4) for f in d["frames"]]


def frame_names(path):
    return [f.get("image") for f in json.load(open(path))["frames"]]


def axis_errors(est, truth):
    rt = truth[:3, :3].T
    t = rt @ (est[:3, 3] - truth[:3, 3])
    r = np.degrees(Rot.from_matrix(rt @ est[:3, :3]).as_rotvec())
    return np.concatenate([t, r])


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    est, truth = load_poses(sys.argv[1]), load_poses(sys.argv[2])
    if len(est) != len(truth):
        # A model's poses.json holds the frames the build used: match them by image.
        names = frame_names(sys.argv[2])
        at = {n: i for i, n in enumerate(names) if n is not None}
        mine = frame_names(sys.argv[1])
        if None in mine or any(n not in at for n in mine):
            sys.exit(f"{sys.argv[1]}: {len(est)} poses, {sys.argv[2]}: {len(truth)}")
        truth = [truth[at[n]] for n in mine]
    e = np.array([axis_errors(a, b) for a, b in zip(est, truth)])
    mm = np.linalg.norm(e[:, :3], axis=1)
    deg = np.linalg.norm(e[:, 3:], axis=1)
    within = int(np.sum((mm <= 1.0) & (deg <= 1.0)))
    print(f"median {np.median(mm):.3f} mm {np.median(deg):.3f} deg, {within}/{len(e)} within 1 mm and 1 deg")
    names = ["x mm", "y mm", "z mm", "pitch deg", "yaw deg", "roll deg"]
    print("        " + "".join(f"{n:>11}" for n in names))
    print("mean    " + "".join(f"{v:11.3f}" for v in e.mean(0)))
    print("RMS     " + "".join(f"{v:11.3f}" for v in np.sqrt((e ** 2).mean(0))))


if __name__ == "__main__":
    main()
