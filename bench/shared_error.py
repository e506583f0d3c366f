"""Which part of a registration's pose error costs new views: copies of a case whose poses keep
or lose the part of the error that frames share.

    python3 bench/shared_error.py CASE POSES.json OUT remove|keep const|W

The error of each frame is taken in its true camera's frame, E_f = T_f^-1 P_f (T: CASE's
truth/poses.json, P: POSES.json, e.g. a model's poses.json), as a rotation vector and an
offset. Its shared part is the video's mean (`const`) or a centred moving average over W frames
(`W`, an odd number). `remove` writes P_f with the shared part taken out (what is left: the
frame-to-frame scatter); `keep` writes T_f with only the shared part (what is left: the error
no frame sees by itself). OUT is a copy of CASE (symbolic links, its truth/ included) with the
new poses.json; build it with the poses trusted and score it on the truth:

    bronchosim build OUT --out M --truth OUT/truth --poses fixed

The held-out frames (model.json cross_validation) against the new views (evaluation.json) say
whether the shared part can be seen in the video at all: a part that lowers new views but not
held-out frames is one no photometric registration on the same frames can find.
"""
import json
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation as Rot


def load(path):
    d = json.load(open(path))
    return d, [np.array(f["camera_to_world"]).reshape(4, 4) for f in d["frames"]]


def shared(x, window):
    """The video's mean (window 0) or a centred moving average of x (frames x 6)."""
    if window <= 0:
        return np.repeat(x.mean(0, keepdims=True), len(x), 0)
    h = window // 2
    return np.array([x[max(0, i - h) : i + h + 1].mean(0) for i in range(len(x))])


def as_matrix(v):
    m = np.eye(4)
    m[:3, :3] = Rot.from_rotvec(v[3:]).as_matrix()
    m[:3, 3] = v[:3]
    return m


def main():
    if len(sys.argv) != 6 or sys.argv[4] not in ("remove", "keep"):
        sys.exit(__doc__)
    case, poses, out, mode, part = sys.argv[1:6]
    window = 0 if part == "const" else int(part)
    _, truth = load(os.path.join(case, "truth", "poses.json"))
    doc, est = load(poses)
    if len(est) != len(truth):
        sys.exit(f"{poses}: {len(est)} poses, {case}/truth/poses.json: {len(truth)}")
    err = [np.linalg.inv(t) @ p for p, t in zip(est, truth)]
    vec = np.array([np.r_[e[:3, 3], Rot.from_matrix(e[:3, :3]).as_rotvec()] for e in err])
    common = shared(vec, window)
    if mode == "remove":
        new = [p @ np.linalg.inv(as_matrix(c)) for p, c in zip(est, common)]
    else:
        new = [t @ as_matrix(c) for t, c in zip(truth, common)]
    os.makedirs(out, exist_ok=True)
    for name in os.listdir(case):
        link = os.path.join(out, name)
        if name != "poses.json" and not os.path.lexists(link):
            os.symlink(os.path.abspath(os.path.join(case, name)), link)
    case_doc = json.load(open(os.path.join(case, "poses.json")))
    for f, m in zip(case_doc["frames"], new):
        f["camera_to_world"] = [float(v) for v in m.flatten()]
    with open(os.path.join(out, "poses.json"), "w") as fh:
        json.dump(case_doc, fh, indent=1)
    deg = np.degrees(common[:, 3:])
    print(
        f"{mode} the shared error ({'mean' if window <= 0 else f'{window}-frame average'}): "
        f"mean pitch / yaw / roll {deg[:, 0].mean():+.3f} / {deg[:, 1].mean():+.3f} / "
        f"{deg[:, 2].mean():+.3f} deg, RMS {np.sqrt((deg ** 2).mean(0)).round(3).tolist()} deg, "
        f"offset RMS {np.sqrt((common[:, :3] ** 2).mean(0)).round(3).tolist()} mm"
    )


if __name__ == "__main__":
    main()
