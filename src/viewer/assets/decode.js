// bronchosim viewer: unpack model-data.js (base64 -> zlib -> typed arrays), rebuild the albedo
// texture and its mip chain exactly as `bronchosim render` does (src/render/texture_sampler.rs),
// and read the inside-distance field.
"use strict";
window.BS = window.BS || {};

BS.decode = (function () {
  function base64Bytes(b64) {
    const bin = atob(b64);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  // zlib inflate with the browser's own DecompressionStream (no fetch: works on file://).
  async function inflate(bytes) {
    if (typeof DecompressionStream === "undefined") {
      throw new Error("this browser has no DecompressionStream (needs Chrome 80, Firefox 113, Safari 16.4 or later)");
    }
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    return new Response(stream).arrayBuffer();
  }

  // The model: meta plus named typed arrays.
  async function model(src) {
    const buf = await inflate(base64Bytes(src.data));
    const meta = src.meta;
    const sec = {};
    for (const s of meta.sections) sec[s.name] = s;
    const f32 = (n) => new Float32Array(buf, sec[n].offset, sec[n].length / 4);
    return {
      meta,
      positions: f32("positions"),
      normals: f32("normals"),
      uvs: f32("uvs"),
      indices: new Uint32Array(buf, sec.indices.offset, sec.indices.length / 4),
      textureCodes: new Uint8Array(buf, sec.texture.offset, sec.texture.length),
      field: new Uint8Array(buf, sec.field.offset, sec.field.length),
      // 255 where a frame saw the texel (absent: nothing to mark).
      coverage: sec.coverage ? new Uint8Array(buf, sec.coverage.offset, sec.coverage.length) : null,
    };
  }

  // sRGB code -> linear, the IEC 61966-2-1 curve in double, rounded to float (as the Rust LUT).
  const SRGB_LUT = (function () {
    const lut = new Float32Array(256);
    for (let c = 0; c < 256; c++) {
      const v = c / 255;
      lut[c] = v <= 0.04045 ? v / 12.92 : Math.pow((v + 0.055) / 1.055, 2.4);
    }
    return lut;
  })();

  // Mip levels of premultiplied RGBA (alpha = coverage; every atlas texel counts as covered,
  // as in Model::load), level L+1 the 2x2 box of level L with texels past an odd edge empty.
  function mipChain(meta, deltas) {
    const t = meta.texture;
    const w = t.width, h = t.height;
    const f = Math.fround;
    const div = [0, 1, 2].map((c) => f(f(t.albedo_scale) * f(t.colour_balance[c])));
    const level0 = new Float32Array(4 * w * h);
    for (let y = 0; y < h; y++) {
      let prev = [0, 0, 0];
      for (let x = 0; x < w; x++) {
        const i = y * w + x;
        for (let c = 0; c < 3; c++) {
          const code = x === 0 ? deltas[3 * i + c] : (deltas[3 * i + c] + prev[c]) & 255;
          prev[c] = code;
          level0[4 * i + c] = SRGB_LUT[code] / div[c];
        }
        level0[4 * i + 3] = 1;
      }
    }
    const levels = [{ width: w, height: h, data: level0 }];
    while (levels.length <= t.max_level) {
      const p = levels[levels.length - 1];
      if (p.width === 1 && p.height === 1) break;
      const lw = Math.ceil(p.width / 2), lh = Math.ceil(p.height / 2);
      const d = new Float32Array(4 * lw * lh);
      for (let y = 0; y < lh; y++) {
        for (let x = 0; x < lw; x++) {
          const o = 4 * (y * lw + x);
          for (let dy = 0; dy < 2; dy++) {
            for (let dx = 0; dx < 2; dx++) {
              const sx = 2 * x + dx, sy = 2 * y + dy;
              if (sx < p.width && sy < p.height) {
                const s = 4 * (sy * p.width + sx);
                for (let k = 0; k < 4; k++) d[o + k] += 0.25 * p.data[s + k];
              }
            }
          }
        }
      }
      levels.push({ width: lw, height: lh, data: d });
    }
    return levels;
  }

  // The inside-distance field: distance(p) in mm at world point p, trilinear, 0 outside.
  function field(meta, bytes) {
    const f = meta.field;
    const [nx, ny, nz] = f.dims;
    const m = f.index_to_world;
    // Invert the 3x3 part of the index -> world affine once.
    const a = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
    const det = a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6]) + a[2] * (a[3] * a[7] - a[4] * a[6]);
    const inv = [
      (a[4] * a[8] - a[5] * a[7]) / det, (a[2] * a[7] - a[1] * a[8]) / det, (a[1] * a[5] - a[2] * a[4]) / det,
      (a[5] * a[6] - a[3] * a[8]) / det, (a[0] * a[8] - a[2] * a[6]) / det, (a[2] * a[3] - a[0] * a[5]) / det,
      (a[3] * a[7] - a[4] * a[6]) / det, (a[1] * a[6] - a[0] * a[7]) / det, (a[0] * a[4] - a[1] * a[3]) / det,
    ];
    const at = (i, j, k) => bytes[i + nx * (j + ny * k)] * f.step_mm;
    return function distance(p) {
      const q = [p[0] - m[3], p[1] - m[7], p[2] - m[11]];
      const x = inv[0] * q[0] + inv[1] * q[1] + inv[2] * q[2];
      const y = inv[3] * q[0] + inv[4] * q[1] + inv[5] * q[2];
      const z = inv[6] * q[0] + inv[7] * q[1] + inv[8] * q[2];
      if (!(x >= 0 && y >= 0 && z >= 0 && x <= nx - 1 && y <= ny - 1 && z <= nz - 1)) return 0;
      const i = Math.min(Math.floor(x), nx - 2), j = Math.min(Math.floor(y), ny - 2), k = Math.min(Math.floor(z), nz - 2);
      const fx = x - i, fy = y - j, fz = z - k;
      let v = 0;
      for (let dz = 0; dz < 2; dz++) for (let dy = 0; dy < 2; dy++) for (let dx = 0; dx < 2; dx++) {
        const w = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy) * (dz ? fz : 1 - fz);
        if (w > 0) v += w * at(i + dx, j + dy, k + dz);
      }
      return v;
    };
  }

  return { model, mipChain, field };
})();
