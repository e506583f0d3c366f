"""The Mitsuba 3 scene of a bronchoscope: the lumen mesh with per-vertex albedo under a
`principled` BSDF, a `spot` emitter at the camera centre along the optical axis, a pinhole
`perspective` sensor with the case's intrinsics, and the `path` integrator.

Mitsuba's camera frame is +x left, +y up, +z forward (perspective.cpp scales the sample plane by
(-0.5, -0.5 aspect)); OpenCV's is +x right, +y down, +z forward, so a camera-to-world pose
becomes Mitsuba's `to_world` by flipping its x and y axes (a 180 degree turn about z).
`check_camera` verifies this convention on every case against pixel-centre ray casts.
"""

import math

import mitsuba as mi
import numpy as np

from case_io import fail

FLIP_XY = np.diag([-1.0, -1.0, 1.0, 1.0])


def set_variant(name):
    """Select the Mitsuba variant (llvm_ad_rgb needs libLLVM >= 16; scalar_rgb runs anywhere)."""
    if name not in mi.variants():
        raise SystemExit(f"error: mitsuba variant {name} is not available ({mi.variants()})")
    mi.set_variant(name)


def oriented_faces(positions, faces, normals):
    """Faces wound so their geometric normal agrees with the vertex normals (into the lumen);
    returns (faces, fraction of faces flipped)."""
    a, b, c = (positions[faces[:, i]] for i in range(3))
    n_geo = np.cross(b - a, c - a)
    n_vtx = normals[faces].sum(axis=1)
    flip = np.einsum("ij,ij->i", n_geo, n_vtx) < 0.0
    out = faces.copy()
    out[flip] = out[flip][:, [0, 2, 1]]
    return out, float(flip.mean())


def lumen_mesh(verts, faces, opts):
    """The truth lumen as a Mitsuba mesh with linear RGB albedo per vertex ("vertex_color")."""
    for k in ("x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"):
        if k not in verts:
            fail(opts.albedo_ply, f'vertex property "{k}" missing')
    pos = np.stack([verts["x"], verts["y"], verts["z"]], axis=1)
    nrm = np.stack([verts["nx"], verts["ny"], verts["nz"]], axis=1)
    alb = np.stack([verts["red"], verts["green"], verts["blue"]], axis=1)
    faces, flipped = oriented_faces(pos, faces, nrm)
    # Zero-area triangles give NaN shading frames in the path tracer.
    a, b, c = (pos[faces[:, i]] for i in range(3))
    keep = np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-12
    faces = faces[keep]
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(
        {
            "type": "principled",
            "base_color": {"type": "mesh_attribute", "name": "vertex_color"},
            "roughness": opts.roughness,
            "specular": opts.specular,
            "metallic": 0.0,
        }
    )
    mesh = mi.Mesh("lumen", len(pos), len(faces), props=props, has_vertex_normals=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(pos.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
    params["vertex_normals"] = mi.Float(nrm.astype(np.float32).ravel())
    mesh.add_attribute("vertex_color", 3, mi.Float(alb.astype(np.float32).ravel()))
    params.update()
    lumen = Lumen(mesh, pos, faces, alb)
    lumen.info = {"faces_flipped_fraction": flipped, "degenerate_faces_dropped": int((~keep).sum())}
    return lumen


class Lumen:
    """The Mitsuba mesh and the arrays it was made from (positions mm, faces, linear albedo)."""

    def __init__(self, mesh, positions, faces, albedo):
        self.mesh, self.positions, self.faces, self.albedo = mesh, positions, faces, albedo
        self.info = {}

    def albedo_at(self, prim, points):
        """Albedo interpolated barycentrically at `points` (n, 3) on triangles `prim` (n,)."""
        f = self.faces[prim]
        a, b, c = (self.positions[f[:, i]] for i in range(3))
        v0, v1, v2 = b - a, c - a, points - a
        d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
        d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
        den = d00 * d11 - d01 * d01
        w1 = (d11 * d20 - d01 * d21) / den
        w2 = (d00 * d21 - d01 * d20) / den
        w = np.clip(np.stack([1.0 - w1 - w2, w1, w2], axis=1), 0.0, 1.0)
        w /= w.sum(axis=1, keepdims=True)
        return np.einsum("ij,ijk->ik", w, self.albedo[f])


def sensor_dict(cam, spp):
    """A pinhole `perspective` sensor with `cam`'s fov and principal point, box pixel filter."""
    w, h = cam["width"], cam["height"]
    if abs(cam["fx"] - cam["fy"]) > 1e-6 * cam["fx"]:
        fail("camera.json", f"fx {cam['fx']} != fy {cam['fy']}: mitsuba's perspective has square pixels")
    # OpenCV pixel centres sit at integer coordinates, Mitsuba's at +0.5: the film centre w/2 is
    # OpenCV's (w - 1)/2. Mitsuba's offsets are fractions of the film, +x to the image right.
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": math.degrees(2.0 * math.atan(0.5 * w / cam["fx"])),
        "principal_point_offset_x": -(cam["cx"] - 0.5 * (w - 1)) / w,
        "principal_point_offset_y": -(cam["cy"] - 0.5 * (h - 1)) / h,
        "near_clip": 0.01,
        "far_clip": 10000.0,
        "film": {
            "type": "hdrfilm",
            "width": w,
            "height": h,
            "pixel_format": "rgb",
            "rfilter": {"type": "box"},
        },
        "sampler": {"type": "independent", "sample_count": spp},
    }


def build_scene(mesh, cam, opts, integrator=None):
    """The scene: mesh, camera (`camera`), spot at the camera (`lamp`), path integrator."""
    return mi.load_dict(
        {
            "type": "scene",
            "integrator": integrator or {"type": "path", "max_depth": opts.max_depth, "hide_emitters": True},
            "lumen": mesh,
            "camera": sensor_dict(cam, opts.spp),
            "lamp": {
                "type": "spot",
                "intensity": {"type": "rgb", "value": [opts.intensity] * 3},
                "beam_width": opts.beam_deg,
                "cutoff_angle": opts.cutoff_deg,
            },
        }
    )


def place(params, camera_to_world):
    """Move the camera and its light to an OpenCV camera-to-world pose."""
    t = mi.ScalarTransform4f((camera_to_world @ FLIP_XY).tolist())
    params["camera.to_world"] = t
    params["lamp.to_world"] = t
    params.update()


def render(scene, params, camera_to_world, spp, seed):
    """Linear RGB radiance (h, w, 3) float64 seen from `camera_to_world`, `spp` paths a pixel."""
    place(params, camera_to_world)
    img = mi.render(scene, spp=spp, seed=seed)
    return np.array(img, dtype=np.float64)[:, :, :3]


def pixel_centre_rays(cam, camera_to_world):
    """World-space unit rays through the pixel centres (OpenCV pinhole): origins, directions."""
    w, h = cam["width"], cam["height"]
    x, y = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d = np.stack([(x - cam["cx"]) / cam["fx"], (y - cam["cy"]) / cam["fy"], np.ones_like(x)], axis=-1)
    d = d.reshape(-1, 3) @ camera_to_world[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(camera_to_world[:3, 3], d.shape)
    return o, d


def pixel_centre_buffers(scene, lumen, cam, camera_to_world):
    """Hit mask, distance along the ray (mm, inf on a miss) and linear albedo at each pixel
    centre's first hit: arrays (h, w), (h, w), (h, w, 3)."""
    o, d = pixel_centre_rays(cam, camera_to_world)
    ray = mi.Ray3f(mi.Point3f(*[o[:, i].astype(np.float32) for i in range(3)]),
                   mi.Vector3f(*[d[:, i].astype(np.float32) for i in range(3)]))
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid(), dtype=bool)
    dist = np.where(hit, np.array(si.t, dtype=np.float64), np.inf)
    alb = np.zeros((hit.size, 3))
    p = np.stack([np.array(c, dtype=np.float64) for c in (si.p.x, si.p.y, si.p.z)], axis=1)
    alb[hit] = lumen.albedo_at(np.array(si.prim_index)[hit], p[hit])
    shape = (cam["height"], cam["width"])
    return hit.reshape(shape), dist.reshape(shape), alb.reshape(shape + (3,))


def check_camera(lumen, cam, opts, camera_to_world):
    """Median relative difference between the depth Mitsuba's sensor sees (aov integrator, 16
    box-filtered samples a pixel) and the pixel-centre ray cast: small only when the sensor's
    axes, fov and principal point match camera.json."""
    scene = build_scene(lumen.mesh, cam, opts, integrator={"type": "aov", "aovs": "dd:depth"})
    params = mi.traverse(scene)
    depth = render(scene, params, camera_to_world, 16, 0)[:, :, 0]
    hit, dist, _ = pixel_centre_buffers(scene, lumen, cam, camera_to_world)
    ok = hit & (depth > 0)
    if ok.sum() < 0.5 * hit.size:
        return float("inf")
    return float(np.median(np.abs(depth[ok] - dist[ok]) / dist[ok]))
