"""A copy of a case seen by the camera turned half a turn about its optical axis.

    python3 bench/turned_case.py CASE OUT

Every frame is rotated 180 degrees about its centre and every pose (poses.json and, when
present, truth/poses.json) is turned with it (camera_to_world times diag(-1, -1, 1, 1)); the CT
and camera.json are linked. The principal point must be the image's centre and the lens's
distortion radial (p1 = p2 = 0), so that the turned camera is the same camera. Registering both
cases tells an error of the scene (it turns with the camera: x and y change sign) from an error
fixed to the pixel grid (it does not); `bench/pose_errors.py` gives the per-axis errors.
"""
import json
import os
import sys

import numpy as np
from PIL import Image

TURN = np.diag([-1.0, -1.0, 1.0, 1.0])


def turned_poses(src, dst):
    d = json.load(open(src))
    for f in d["frames"]:
        m = np.array(f["camera_to_world"]).reshape(4, 4) @ TURN
        f["camera_to_world"] = list(m.flatten())
    json.dump(d, open(dst, "w"), indent=1)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    case, out = sys.argv[1], sys.argv[2]
    cam = json.load(open(os.path.join(case, "camera.json")))
    if (2 * cam["cx"] + 1, 2 * cam["cy"] + 1) != (cam["width"], cam["height"]):
        sys.exit(f"{case}/camera.json: the principal point is not the image's centre")
    if cam.get("p1", 0.0) != 0.0 or cam.get("p2", 0.0) != 0.0:
        sys.exit(f"{case}/camera.json: tangential distortion does not turn with the image")
    if os.path.exists(out):
        sys.exit(f"{out}: exists")
    os.makedirs(os.path.join(out, "frames"))
    for name in ["camera.json", "ct.nii.gz"]:
        os.symlink(os.path.realpath(os.path.join(case, name)), os.path.join(out, name))
    turned_poses(os.path.join(case, "poses.json"), os.path.join(out, "poses.json"))
    if os.path.exists(os.path.join(case, "truth", "poses.json")):
        os.makedirs(os.path.join(out, "truth"))
        turned_poses(os.path.join(case, "truth", "poses.json"), os.path.join(out, "truth", "poses.json"))
    for f in json.load(open(os.path.join(case, "poses.json")))["frames"]:
        if "image" not in f:
            sys.exit(f"{case}/poses.json: frames from a video are not supported")
        img = Image.open(os.path.join(case, f["image"]))
        dst = os.path.join(out, f["image"])
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        img.rotate(180).save(dst)


if __name__ == "__main__":
    main()
