"""A copy of a case whose given poses lose some axes of their error: which part of a tracker's
error the registration cannot undo.

    python3 bench/drop_pose_error.py CASE OUT AXIS[,AXIS...]

AXIS is one of x, y, z (mm, the true camera's right, down, view) and pitch, yaw, roll (degrees,
about those axes), as bench/pose_errors.py reports them. Each frame's given pose P is written
back as T E', where T is its true pose (CASE/truth/poses.json), E = T^-1 P its error in the true
camera's frame and E' that error with the named axes set to 0 (the rotation as a rotation
vector). OUT is a copy of CASE (symbolic links, truth/ included) with the new poses.json; build
it as the case itself:

    bronchosim build OUT --out M --truth OUT/truth

A registration that ends much nearer the truth from OUT than from CASE cannot undo the dropped
part of the error by itself (e.g. the roll about a round airway's axis).
"""
import json
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation as Rot

AXES = ["x", "y", "z", "pitch", "yaw", "roll"]


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    case, out, names = sys.argv[1], sys.argv[2], sys.argv[3].split(",")
    bad = [a for a in names if a not in AXES]
    if bad:
        sys.exit(f"{sys.argv[3]}: unknown axis {bad[0]} (expected {', '.join(AXES)})")
    drop = [AXES.index(a) for a in names]
    given = json.load(open(os.path.join(case, "poses.json")))
    truth = json.load(open(os.path.join(case, "truth", "poses.json")))
    if len(given["frames"]) != len(truth["frames"]):
        sys.exit(f"{case}: poses.json and truth/poses.json hold different numbers of frames")
    os.makedirs(out, exist_ok=False)
    for name in os.listdir(case):
        if name != "poses.json":
            os.symlink(os.path.abspath(os.path.join(case, name)), os.path.join(out, name))
    for f, t in zip(given["frames"], truth["frames"]):
        p = np.array(f["camera_to_world"]).reshape(4, 4)
        tt = np.array(t["camera_to_world"]).reshape(4, 4)
        e = np.linalg.inv(tt) @ p
        err = np.concatenate([e[:3, 3], Rot.from_matrix(e[:3, :3]).as_rotvec()])
        err[drop] = 0.0
        e[:3, 3] = err[:3]
        e[:3, :3] = Rot.from_rotvec(err[3:]).as_matrix()
        f["camera_to_world"] = (tt @ e).reshape(-1).tolist()
    with open(os.path.join(out, "poses.json"), "w") as fh:
        json.dump(given, fh, indent=1)


if __name__ == "__main__":
    main()
