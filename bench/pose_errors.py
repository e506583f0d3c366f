"""Pose errors per camera axis: how far the poses in a poses.json are from a case's truth.

    python3 bench/pose_errors.py POSES.json TRUTH_POSES.json [GIVEN_POSES.json]

For each frame the error of the estimated pose in the true camera's axes: the centre's offset
(x right, y down, z along the view, mm) and the rotation vector of R_true^T R_est (pitch about
x, yaw about y, roll about z, degrees), as `registration::pose_error_axes`. Prints the median
centre and rotation errors, the frames within 1 mm and 1 deg, and the mean and RMS per axis: a
mean near the RMS is an error the frames share (the whole video off the same way), which held
out frames cannot show and new views pay for.

With the poses the registration was given (the case's poses.json), also per axis how the
remaining error follows the given poses' error: their correlation and the share of it left
(the least-squares slope). A share that stays as rounds are added is an error the cost is flat
along, not one still on its way out.
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


def matched(path, est_path, n_est):
    """The poses of `path` for the frames of `est_path` (a model's poses.json holds the frames
    the build used: matched by image)."""
    poses = load_poses(path)
    if len(poses) == n_est:
        return poses
    names = frame_names(path)
    at = {n: i for i, n in enumerate(names) if n is not None}
    mine = frame_names(est_path)
    if None in mine or any(n not in at for n in mine):
        sys.exit(f"{est_path}: {n_est} poses, {path}: {len(poses)}")
    return [poses[at[n]] for n in mine]


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    est = load_poses(sys.argv[1])
    truth = matched(sys.argv[2], sys.argv[1], len(est))
    e = np.array([axis_errors(a, b) for a, b in zip(est, truth)])
    mm = np.linalg.norm(e[:, :3], axis=1)
    deg = np.linalg.norm(e[:, 3:], axis=1)
    within = int(np.sum((mm <= 1.0) & (deg <= 1.0)))
    print(f"median {np.median(mm):.3f} mm {np.median(deg):.3f} deg, {within}/{len(e)} within 1 mm and 1 deg")
    names = ["x mm", "y mm", "z mm", "pitch deg", "yaw deg", "roll deg"]
    print("        " + "".join(f"{n:>11}" for n in names))
    print("mean    " + "".join(f"{v:11.3f}" for v in e.mean(0)))
    print("RMS     " + "".join(f"{v:11.3f}" for v in np.sqrt((e ** 2).mean(0))))
    if len(sys.argv) == 4:
        given = matched(sys.argv[3], sys.argv[1], len(est))
        g = np.array([axis_errors(a, b) for a, b in zip(given, truth)])
        corr = [np.corrcoef(e[:, k], g[:, k])[0, 1] for k in range(6)]
        left = [e[:, k] @ g[:, k] / (g[:, k] @ g[:, k]) for k in range(6)]
        print("given   " + "".join(f"{v:11.3f}" for v in np.sqrt((g ** 2).mean(0))))
        print("corr    " + "".join(f"{v:11.2f}" for v in corr))
        print("left    " + "".join(f"{v:11.3f}" for v in left))


if __name__ == "__main__":
    main()
