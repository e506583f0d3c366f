"""A copy of a case whose given poses lose some axes of their error: which part of a tracker's
error the registration cannot undo.

    python3 bench/drop_pose_error.py CASE OUT AXIS[,AXIS...] [--from POSES.json] [--frames A-B]

AXIS is one of x, y, z (mm, the true camera's right, down, view) and pitch, yaw, roll (degrees,
about those axes), as bench/pose_errors.py reports them, or `all`. `--from` takes the poses
from POSES.json (e.g. a model's poses.json, the poses a build registered) instead of CASE's
poses.json; `--frames A-B` drops the error of frames A to B only (counted from 0, both
included), the other frames keep theirs. Each frame's given pose P is written
back as T E', where T is its true pose (CASE/truth/poses.json), E = T^-1 P its error in the true
camera's frame and E' that error with the named axes set to 0 (the rotation as a rotation
vector). OUT is a copy of CASE (symbolic links, truth/ included) with the new poses.json; build
it as the case itself:

    bronchosim build OUT --out M --truth OUT/truth

A registration that ends much nearer the truth from OUT than from CASE cannot undo the dropped
part of the error by itself (e.g. the roll about a round airway's axis). With `--from` a
model's poses, built with `--poses fixed`, shows what each part of the registered poses' error
costs the new views:

    python3 bench/drop_pose_error.py CASE OUT all --from M/poses.json --frames 0-16
    bronchosim build OUT --out M2 --poses fixed
"""
import json
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation as Rot

AXES = ["x", "y", "z", "pitch", "yaw", "roll"]


def main():
    args = sys.argv[1:]
    options = {}
    for flag in ("--from", "--frames"):
        if flag in args:
            i = args.index(flag)
            if i + 1 >= len(args):
                sys.exit(f"{flag} needs a value\n{__doc__}")
            options[flag] = args[i + 1]
            del args[i : i + 2]
    if len(args) != 3:
        sys.exit(__doc__)
    case, out, names = args[0], args[1], args[2].split(",")
    if names == ["all"]:
        names = AXES
    bad = [a for a in names if a not in AXES]
    if bad:
        sys.exit(f"{args[2]}: unknown axis {bad[0]} (expected {', '.join(AXES)} or all)")
    drop = [AXES.index(a) for a in names]
    source = options.get("--from", os.path.join(case, "poses.json"))
    given = json.load(open(source))
    truth = json.load(open(os.path.join(case, "truth", "poses.json")))
    if len(given["frames"]) != len(truth["frames"]):
        sys.exit(
            f"{source}: {len(given['frames'])} poses, "
            f"{case}/truth/poses.json {len(truth['frames'])}"
        )
    first, last = 0, len(truth["frames"]) - 1
    if "--frames" in options:
        try:
            first, last = (int(v) for v in options["--frames"].split("-"))
        except ValueError:
            sys.exit(f"--frames {options['--frames']}: expected A-B, e.g. 0-16")
    os.makedirs(out, exist_ok=False)
    for name in os.listdir(case):
        if name != "poses.json":
            os.symlink(os.path.abspath(os.path.join(case, name)), os.path.join(out, name))
    frames = []
    for i, (f, t) in enumerate(zip(given["frames"], truth["frames"])):
        p = np.array(f["camera_to_world"]).reshape(4, 4)
        # A case's own poses keep every field; a model's keep what the case format holds.
        if "--from" in options:
            frames.append({"image": t["image"], "camera_to_world": f["camera_to_world"]})
        else:
            frames.append(dict(f))
        if not first <= i <= last:
            continue
        tt = np.array(t["camera_to_world"]).reshape(4, 4)
        e = np.linalg.inv(tt) @ p
        err = np.concatenate([e[:3, 3], Rot.from_matrix(e[:3, :3]).as_rotvec()])
        err[drop] = 0.0
        e[:3, 3] = err[:3]
        e[:3, :3] = Rot.from_rotvec(err[3:]).as_matrix()
        frames[-1]["camera_to_world"] = (tt @ e).reshape(-1).tolist()
    with open(os.path.join(out, "poses.json"), "w") as fh:
        head = {} if "--from" in options else given
        json.dump({**head, "frames": frames}, fh, indent=1)


if __name__ == "__main__":
    main()
