"""A copy of a case whose frames START .. START+COUNT-1 are black: the lens against the wall,
or fluid over it, for COUNT frames.

    python3 bench/blackout.py CASE OUT START COUNT

Every other file of CASE (ct, camera.json, poses.json, truth/, the other frames) is linked.
With a case without a tracker (poses.json holding the first pose alone) build it with
`bronchosim build OUT --out M --poses first --truth OUT/truth`; `bench/pose_errors.py
M/poses.json OUT/truth/poses.json` gives the errors.
"""
import os
import sys

import numpy as np
from PIL import Image


def main():
    case, out, start, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    os.makedirs(os.path.join(out, "frames"), exist_ok=False)
    for name in os.listdir(case):
        if name != "frames":
            os.symlink(os.path.abspath(os.path.join(case, name)), os.path.join(out, name))
    names = sorted(os.listdir(os.path.join(case, "frames")))
    for i, name in enumerate(names):
        src = os.path.abspath(os.path.join(case, "frames", name))
        dst = os.path.join(out, "frames", name)
        if start <= i < start + count:
            size = Image.open(src).size
            Image.fromarray(np.zeros((size[1], size[0], 3), np.uint8)).save(dst)
        else:
            os.symlink(src, dst)


if __name__ == "__main__":
    main()
