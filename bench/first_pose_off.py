"""A copy of a case without a tracker whose one given pose, the first frame's, is off.

    python3 bench/first_pose_off.py CASE OUT MM DEG

OUT/poses.json holds the first frame's true pose (CASE/truth/poses.json) with its centre moved
MM along the camera's (1, 1, 1) direction and the camera turned DEG about its (1, -1, 1) axis:
a first pose aligned by hand. Everything else of CASE (ct, camera.json, frames/, truth/) is
linked. Build it with `bronchosim build OUT --out M --poses first [--trust-first-pose] --truth
OUT/truth`; `bench/pose_errors.py M/poses.json OUT/truth/poses.json` gives the errors.
"""
import json
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation as Rot


def main():
    case, out, mm, deg = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
    os.makedirs(out, exist_ok=False)
    for name in os.listdir(case):
        if name != "poses.json":
            os.symlink(os.path.abspath(os.path.join(case, name)), os.path.join(out, name))
    truth = json.load(open(os.path.join(case, "truth", "poses.json")))
    first = truth["frames"][0]
    m = np.array(first["camera_to_world"], dtype=float).reshape(4, 4)
    r = m[:3, :3]
    m[:3, 3] += r @ (np.ones(3) / np.sqrt(3.0)) * mm
    axis = np.array([1.0, -1.0, 1.0]) / np.sqrt(3.0)
    m[:3, :3] = r @ Rot.from_rotvec(np.radians(deg) * axis).as_matrix()
    first["camera_to_world"] = m.reshape(-1).tolist()
    truth["frames"] = [first]
    json.dump(truth, open(os.path.join(out, "poses.json"), "w"), indent=1)


if __name__ == "__main__":
    main()
