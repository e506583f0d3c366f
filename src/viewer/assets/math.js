// bronchosim viewer: poses and small vector maths.
// A pose is camera -> world as bronchosim writes it: 16 numbers, row-major, OpenCV camera axes
// (x right, y down, z forward), world mm. Its rotation columns are the camera's axes in world.
"use strict";
window.BS = window.BS || {};

BS.math = (function () {
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const cross = (a, b) => [
    a[1] * b[2] - a[2] * b[1],
    a[2] * b[0] - a[0] * b[2],
    a[0] * b[1] - a[1] * b[0],
  ];
  const norm = (a) => Math.sqrt(dot(a, a));
  const normalize = (a) => {
    const n = norm(a);
    return n > 0 ? scale(a, 1 / n) : a.slice();
  };

  // The camera's axes (world) and centre of a row-major camera -> world matrix.
  function axes(m) {
    return {
      x: [m[0], m[4], m[8]],
      y: [m[1], m[5], m[9]],
      z: [m[2], m[6], m[10]],
      t: [m[3], m[7], m[11]],
    };
  }

  // A pose from the camera's axes and centre (x is rebuilt so the frame stays right-handed
  // and orthonormal: z is kept, y is made perpendicular to it).
  function fromAxes(z, y, t) {
    const zz = normalize(z);
    let yy = sub(y, scale(zz, dot(y, zz)));
    if (norm(yy) < 1e-9) yy = Math.abs(zz[0]) < 0.9 ? cross(zz, [1, 0, 0]) : cross(zz, [0, 1, 0]);
    yy = normalize(yy);
    const xx = cross(yy, zz);
    return [xx[0], yy[0], zz[0], t[0], xx[1], yy[1], zz[1], t[1], xx[2], yy[2], zz[2], t[2], 0, 0, 0, 1];
  }

  // Rotate vector v about unit axis k by angle a (radians, right-handed; Rodrigues).
  function rotate(v, k, a) {
    const c = Math.cos(a), s = Math.sin(a);
    const kv = cross(k, v), kd = dot(k, v) * (1 - c);
    return [v[0] * c + kv[0] * s + k[0] * kd, v[1] * c + kv[1] * s + k[1] * kd, v[2] * c + kv[2] * s + k[2] * kd];
  }

  // The pose turned by `a` radians about its own axis `which` ("x": pitch, "y": yaw, "z": roll).
  function turn(m, which, a) {
    const ax = axes(m);
    const k = ax[which];
    return fromAxes(rotate(ax.z, k, a), rotate(ax.y, k, a), ax.t);
  }

  // The pose moved to centre t.
  function moved(m, t) {
    const r = m.slice();
    r[3] = t[0]; r[7] = t[1]; r[11] = t[2];
    return r;
  }

  // Blend of two poses (f in [0, 1]): centres linearly, axes linearly then re-orthonormalised
  // (the autopilot's poses are close together, so this is as good as a slerp).
  function blend(a, b, f) {
    const A = axes(a), B = axes(b);
    const mix = (p, q) => add(scale(p, 1 - f), scale(q, f));
    return fromAxes(mix(A.z, B.z), mix(A.y, B.y), mix(A.t, B.t));
  }

  // Parse "#pose=16 numbers&camera=W,H,fx,fy,cx,cy" (either part optional).
  function parseHash(hash) {
    const out = { pose: null, camera: null, errors: [] };
    const h = (hash || "").replace(/^#/, "");
    for (const part of h.split("&")) {
      if (!part) continue;
      const eq = part.indexOf("=");
      const key = eq < 0 ? part : part.slice(0, eq);
      const nums = (eq < 0 ? "" : decodeURIComponent(part.slice(eq + 1)))
        .split(/[,\s]+/).filter((s) => s !== "").map(Number);
      if (key === "pose") {
        if (nums.length === 16 && nums.every(Number.isFinite)) out.pose = nums;
        else out.errors.push("pose: expected 16 numbers (camera_to_world, row-major)");
      } else if (key === "camera") {
        const ok = nums.length === 6 && nums.every(Number.isFinite) && nums[0] >= 1 && nums[1] >= 1 && nums[2] > 0 && nums[3] > 0;
        if (ok) out.camera = { width: Math.round(nums[0]), height: Math.round(nums[1]), fx: nums[2], fy: nums[3], cx: nums[4], cy: nums[5] };
        else out.errors.push("camera: expected W,H,fx,fy,cx,cy with positive size and focal lengths");
      }
    }
    return out;
  }

  // Shortest text that reads back to the same double.
  const num = (v) => String(Math.abs(v) < 1e-12 ? 0 : v);

  function formatHash(pose, camera) {
    let s = "#pose=" + pose.map(num).join(",");
    if (camera) s += "&camera=" + [camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy].map(num).join(",");
    return s;
  }

  // The pose in poses.json form (for `bronchosim render --views`).
  function posesJson(pose, image) {
    const rows = [0, 1, 2, 3].map((r) => "    " + pose.slice(4 * r, 4 * r + 4).map((v) => Number(v.toFixed(6))).join(", "));
    return '{ "frames": [\n  { "image": "' + image + '",\n    "camera_to_world": [\n' + rows.join(",\n") + "\n    ] }\n] }\n";
  }

  return { dot, add, sub, scale, cross, norm, normalize, axes, fromAxes, rotate, turn, moved, blend, parseHash, formatHash, posesJson };
})();
