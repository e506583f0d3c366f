"""Memory to request for a case's build job, from the case's size in its inspect.json.

Peak resident memory of `bronchosim build` (release, `/usr/bin/time -v`), measured on phantom
cases (`bronchosim phantom`, 2 cores):

| CT (voxels)              | frames          | triangles, texels   | peak   |
|--------------------------|-----------------|---------------------|--------|
| 225x169x181 (6.88 M)     | 12 of 96x96     | 49 k, 0.56 M        | 193 MB |
| 225x169x181 (6.88 M)     | 80 of 320x320   | 49 k, 0.56 M        | 410 MB |
| 352x287x312 (31.5 M), ATM_305's airway | 80 of 320x320 | 166 k, 2.2 M | 965 MB |

The three points fix peak = 35 MB + 22.5 MB per million CT voxels + 26.9 MB per million frame
pixels (frames times width times height). The CT term also carries the mesh and atlas, which grow
with the airway; on a full chest CT, where the airway fills less of the grid, it overestimates.
The request is 1.5 times that, at least 1 GB, and doubles with each retry (`attempt`).
"""
import json
import math

BASE_MB = 35.0
MB_PER_MVOXEL = 22.5
MB_PER_MPIXEL = 26.9
HEADROOM = 1.5
MIN_MB = 1000
# Before inspect has run (a dry run plans jobs ahead): enough for a 512x512x400 CT with 300
# frames of 640x480.
UNKNOWN_MB = 8000


def build_peak_mb(inspection: dict) -> float:
    """Expected peak (MB) of `bronchosim build` on the case `inspect --json` described."""
    nx, ny, nz = inspection["ct"]["dims"]
    width, height = inspection["camera"]["size"]
    frames = inspection["video"]["frames"]
    return (BASE_MB + MB_PER_MVOXEL * nx * ny * nz / 1e6
            + MB_PER_MPIXEL * frames * width * height / 1e6)


def build_mem_mb(inspect_json, attempt: int = 1) -> int:
    """Memory request (MB) of a build job; `inspect_json` is the case's inspect.json path."""
    try:
        with open(inspect_json) as f:
            peak = build_peak_mb(json.load(f))
    except (OSError, ValueError, KeyError, TypeError):
        return UNKNOWN_MB * attempt
    return max(MIN_MB, int(math.ceil(HEADROOM * peak / 100.0)) * 100) * attempt
