// bronchosim viewer: the WebGL2 renderer (surface pass into a float target, reduction of the
// view's mean luminance, composite with inter-reflection, exposure and sRGB to the canvas).
"use strict";
window.BS = window.BS || {};

BS.Renderer = (function () {
  const M = BS.math;
  const NEAR_MM = 0.1, FAR_MM = 2000;

  function compile(gl, vs, fs) {
    const prog = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const sh = gl.createShader(type);
      gl.shaderSource(sh, src);
      gl.compileShader(sh);
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(sh));
      gl.attachShader(prog, sh);
    }
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(prog));
    const loc = {};
    const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) {
      const name = gl.getActiveUniform(prog, i).name.replace(/\[0\]$/, "");
      loc[name] = gl.getUniformLocation(prog, name);
    }
    return { prog, loc };
  }

  function floatTexture(gl, format, w, h, data) {
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.texImage2D(gl.TEXTURE_2D, 0, format, w, h, 0, gl.RGBA, gl.FLOAT, data || null);
    return tex;
  }

  // One byte per texel (the coverage map), sampled bilinearly so marked walls have soft edges.
  function byteTexture(gl, w, h, data) {
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.R8, w, h, 0, gl.RED, gl.UNSIGNED_BYTE, data);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 4);
    return tex;
  }

  // The paper's viewpoint weights for a new camera, as src/shading/paper/viewpoints.rs blends
  // them (k = 1: the nearest camera centre, ties by viewing direction).
  function psiWeights(vps, pose, k, directionMm) {
    const A = M.axes(pose);
    const v = M.normalize(A.z);
    if (k === 1) {
      let best = -1, bd = Infinity, bc = -Infinity;
      vps.forEach((p, i) => {
        const d = M.norm(M.sub(p.centre, A.t)), c = M.dot(p.dir, v);
        if (best < 0 || d < bd - 1e-9 || (d <= bd + 1e-9 && c > bc)) { best = i; bd = d; bc = c; }
      });
      return best < 0 ? [] : [[best, 1]];
    }
    const pen = vps.map((p, i) => [i, M.norm(M.sub(p.centre, A.t)) + directionMm * Math.max(1 - M.dot(p.dir, v), 0)]);
    pen.sort((a, b) => a[1] - b[1] || a[0] - b[0]);
    if (pen.length === 0) return [];
    if (pen[0][1] <= 1e-9) return [[pen[0][0], 1]];
    const thresh = pen.length > k ? pen[k][1] : pen[pen.length - 1][1] * 1.5;
    const out = pen.slice(0, k).map(([i, p]) => [i, Math.max(1 - p / thresh, 0) / p]).filter((x) => x[1] > 0);
    const sum = out.reduce((s, x) => s + x[1], 0);
    if (sum <= 0) {
      const n = Math.min(k, vps.length);
      return Array.from({ length: n }, (_, j) => [j, 1 / n]);
    }
    return out.map(([i, w]) => [i, w / sum]);
  }

  class Renderer {
    constructor(canvas, model) {
      const gl = canvas.getContext("webgl2", { antialias: false, alpha: false, depth: false, preserveDrawingBuffer: true });
      if (!gl) throw new Error("this browser has no WebGL2");
      this.floatTargets = !!gl.getExtension("EXT_color_buffer_float");
      if (!this.floatTargets && !gl.getExtension("EXT_color_buffer_half_float")) {
        throw new Error("WebGL2 without float render targets (EXT_color_buffer_float)");
      }
      this.gl = gl;
      this.canvas = canvas;
      this.model = model;
      this.meta = model.meta;
      this.surface = compile(gl, BS.shaders.surfaceVS, BS.shaders.surfaceFS(model.meta.shading));
      this.depthOnly = compile(gl, BS.shaders.surfaceVS, BS.shaders.depthFS);
      this.reduce = compile(gl, BS.shaders.quadVS, BS.shaders.reduceFS);
      this.composite = compile(gl, BS.shaders.quadVS, BS.shaders.compositeFS);
      this.uploadMesh();
      this.uploadTexture();
      this.texCoverage = model.coverage ? byteTexture(gl, this.meta.texture.width, this.meta.texture.height, model.coverage) : null;
      const sh = this.meta.shading;
      if (sh.kind === "paper") {
        this.viewpoints = sh.viewpoints.map((p) => {
          const a = M.axes(p.camera_to_world);
          return { centre: a.t, dir: M.normalize(a.z), psi: p };
        });
      }
      this.size = null;
    }

    uploadMesh() {
      const gl = this.gl, m = this.model;
      this.vao = gl.createVertexArray();
      gl.bindVertexArray(this.vao);
      [[m.positions, 3], [m.normals, 3], [m.uvs, 2]].forEach(([data, n], loc) => {
        const b = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, b);
        gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
        gl.enableVertexAttribArray(loc);
        gl.vertexAttribPointer(loc, n, gl.FLOAT, false, 0, 0);
      });
      const ib = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, m.indices, gl.STATIC_DRAW);
      this.indexCount = m.indices.length;
      gl.bindVertexArray(null);
    }

    // Level 0 in one texture, levels 1.. side by side in another (their sizes round up, as
    // the Rust mip chain's do, which a GL mip chain cannot hold).
    uploadTexture() {
      const gl = this.gl;
      const levels = BS.decode.mipChain(this.meta, this.model.textureCodes);
      const big = levels[0].width * levels[0].height > 4 << 20;
      // Half floats keep a 4k atlas at 128 MB of GPU memory; 11 bits are far below 8-bit output.
      const fmt = big ? gl.RGBA16F : gl.RGBA32F;
      this.tex0 = floatTexture(gl, fmt, levels[0].width, levels[0].height, levels[0].data);
      let w = 0, h = 1;
      this.levelOffset = [0, 0];
      this.levelSize = [levels[0].width, levels[0].height];
      for (let l = 1; l < levels.length; l++) {
        this.levelOffset.push(w, 0);
        this.levelSize.push(levels[l].width, levels[l].height);
        w += levels[l].width;
        h = Math.max(h, levels[l].height);
      }
      const packed = new Float32Array(4 * Math.max(w, 1) * h);
      for (let l = 1; l < levels.length; l++) {
        const L = levels[l], x0 = this.levelOffset[2 * l];
        for (let y = 0; y < L.height; y++) {
          packed.set(L.data.subarray(4 * y * L.width, 4 * (y + 1) * L.width), 4 * (y * w + x0));
        }
      }
      this.texMips = floatTexture(gl, fmt, Math.max(w, 1), h, packed);
      this.levels = levels.length;
      while (this.levelSize.length < 16) { this.levelSize.push(1); this.levelOffset.push(0); }
    }

    // Render targets for a W x H view: the surface (float RGBA + depth) and the reduction chain.
    resize(w, h) {
      if (this.size && this.size[0] === w && this.size[1] === h) return;
      const gl = this.gl;
      const fmt = this.floatTargets ? gl.RGBA32F : gl.RGBA16F;
      for (const t of this.targets || []) { gl.deleteTexture(t.tex); gl.deleteFramebuffer(t.fb); }
      if (this.depth) gl.deleteRenderbuffer(this.depth);
      const target = (tw, th) => {
        const tex = floatTexture(gl, fmt, tw, th, null);
        const fb = gl.createFramebuffer();
        gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
        gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
        return { tex, fb, w: tw, h: th };
      };
      this.targets = [target(w, h)];
      this.depth = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, this.depth);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, w, h);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, this.depth);
      if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) throw new Error("float render target incomplete");
      let [rw, rh] = [w, h];
      while (rw > 1 || rh > 1) {
        rw = Math.ceil(rw / 4); rh = Math.ceil(rh / 4);
        this.targets.push(target(rw, rh));
      }
      if (this.targets.length === 1) this.targets.push(target(1, 1));
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      this.size = [w, h];
    }

    setShading(view) {
      const gl = this.gl, u = this.surface.loc, sh = this.meta.shading;
      gl.uniform1i(u.uAlbedoOnly, view.albedoOnly ? 1 : 0);
      if (sh.kind === "calibrated") {
        gl.uniform1i(u.uKind, 0);
        gl.uniform1f(u.uCosEdge, sh.cos_theta_edge);
        gl.uniform3fv(u.uAmbient, sh.ambient);
        gl.uniform3fv(u.uSpecK, sh.specular ? sh.specular.k : [0, 0, 0]);
        gl.uniform1f(u.uSpecAlpha, sh.specular ? sh.specular.alpha : 1);
        return;
      }
      gl.uniform1i(u.uKind, 1);
      const w = psiWeights(this.viewpoints, view.pose, sh.k, sh.direction_mm).slice(0, 4);
      const C = new Float32Array(48), D = new Float32Array(36), Z = new Float32Array(8), W = new Float32Array(4);
      w.forEach(([i, wt], v) => {
        const p = this.viewpoints[i].psi;
        for (let c = 0; c < 3; c++) {
          C.set(p.c[c], 4 * (3 * v + c));
          D.set(p.d[c], 3 * (3 * v + c));
        }
        Z[2 * v] = p.z_min; Z[2 * v + 1] = p.z_max; W[v] = wt;
      });
      this.lastPsi = w;
      gl.uniform1i(u.uPsiCount, w.length);
      gl.uniform4fv(u.uPsiC, C);
      gl.uniform3fv(u.uPsiD, D);
      gl.uniform2fv(u.uPsiZ, Z);
      gl.uniform1fv(u.uPsiW, W);
    }

    // The vertex shader's camera uniforms.
    setCamera(u, A, worldToCam, cam) {
      const gl = this.gl;
      gl.uniform3fv(u.uOrigin, A.t);
      gl.uniformMatrix3fv(u.uWorldToCam, false, worldToCam);
      if (u.uIntr) gl.uniform4f(u.uIntr, cam.fx, cam.fy, cam.cx, cam.cy);
      if (u.uSize) gl.uniform2f(u.uSize, cam.width, cam.height);
      gl.uniform2f(u.uDepth, NEAR_MM, FAR_MM);
    }

    // Draw `view` = { pose, camera {width, height, fx, fy, cx, cy}, gain, autoExposure,
    // albedoOnly } into the canvas (whose size must be the camera's).
    draw(view) {
      const gl = this.gl, cam = view.camera;
      this.resize(cam.width, cam.height);
      const A = M.axes(view.pose);
      const camToWorld = [A.x[0], A.x[1], A.x[2], A.y[0], A.y[1], A.y[2], A.z[0], A.z[1], A.z[2]];
      const worldToCam = [A.x[0], A.y[0], A.z[0], A.x[1], A.y[1], A.z[1], A.x[2], A.y[2], A.z[2]];
      // Surface pass.
      const s = this.surface;
      gl.bindFramebuffer(gl.FRAMEBUFFER, this.targets[0].fb);
      gl.viewport(0, 0, cam.width, cam.height);
      gl.clearColor(0, 0, 0, 0);
      gl.clearDepth(1);
      gl.enable(gl.DEPTH_TEST);
      gl.depthFunc(gl.LESS);
      gl.disable(gl.CULL_FACE);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      // Depth first (no colour), then shade only the nearest surface of each pixel.
      const d = this.depthOnly;
      gl.useProgram(d.prog);
      this.setCamera(d.loc, A, worldToCam, cam);
      gl.colorMask(false, false, false, false);
      gl.bindVertexArray(this.vao);
      gl.drawElements(gl.TRIANGLES, this.indexCount, gl.UNSIGNED_INT, 0);
      gl.colorMask(true, true, true, true);
      gl.depthFunc(gl.LEQUAL);
      gl.depthMask(false);
      gl.useProgram(s.prog);
      this.setCamera(s.loc, A, worldToCam, cam);
      gl.uniformMatrix3fv(s.loc.uCamToWorld, false, camToWorld);
      gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, this.tex0);
      gl.activeTexture(gl.TEXTURE1); gl.bindTexture(gl.TEXTURE_2D, this.texMips);
      gl.uniform1i(s.loc.uTex0, 0);
      gl.uniform1i(s.loc.uTexMips, 1);
      gl.activeTexture(gl.TEXTURE2); gl.bindTexture(gl.TEXTURE_2D, this.texCoverage);
      gl.uniform1i(s.loc.uCoverage, 2);
      gl.uniform1i(s.loc.uMarkUnseen, view.markUnseen && this.texCoverage ? 1 : 0);
      gl.activeTexture(gl.TEXTURE0);
      gl.uniform2iv(s.loc.uLevelSize, new Int32Array(this.levelSize.slice(0, 16)));
      gl.uniform2iv(s.loc.uLevelOffset, new Int32Array(this.levelOffset.slice(0, 16)));
      gl.uniform1i(s.loc.uLevels, this.levels);
      gl.uniform2f(s.loc.uAtlasSize, this.meta.texture.width, this.meta.texture.height);
      gl.uniform1f(s.loc.uTexelMm, this.meta.texture.texel_mm);
      this.setShading(view);
      gl.drawElements(gl.TRIANGLES, this.indexCount, gl.UNSIGNED_INT, 0);
      gl.bindVertexArray(null);
      gl.depthMask(true);
      gl.disable(gl.DEPTH_TEST);
      // Reduction passes.
      const r = this.reduce;
      gl.useProgram(r.prog);
      gl.activeTexture(gl.TEXTURE0);
      gl.uniform1i(r.loc.uSrc, 0);
      for (let i = 1; i < this.targets.length; i++) {
        const src = this.targets[i - 1], dst = this.targets[i];
        gl.bindFramebuffer(gl.FRAMEBUFFER, dst.fb);
        gl.viewport(0, 0, dst.w, dst.h);
        gl.bindTexture(gl.TEXTURE_2D, src.tex);
        gl.uniform2i(r.loc.uSrcSize, src.w, src.h);
        gl.uniform1i(r.loc.uFirst, i === 1 ? 1 : 0);
        gl.drawArrays(gl.TRIANGLES, 0, 3);
      }
      // Composite to the canvas.
      const c = this.composite, sh = this.meta.shading;
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.viewport(0, 0, cam.width, cam.height);
      gl.useProgram(c.prog);
      gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, this.targets[0].tex);
      gl.activeTexture(gl.TEXTURE1); gl.bindTexture(gl.TEXTURE_2D, this.targets[this.targets.length - 1].tex);
      gl.uniform1i(c.loc.uSurface, 0);
      gl.uniform1i(c.loc.uSums, 1);
      const kappa = sh.kind === "calibrated" && sh.interreflection && !view.albedoOnly;
      gl.uniform1i(c.loc.uHasKappa, kappa ? 1 : 0);
      gl.uniform3fv(c.loc.uKappa, kappa ? sh.interreflection : [0, 0, 0]);
      gl.uniform1f(c.loc.uGain, view.albedoOnly ? 1 : view.gain);
      const ae = this.autoExposure();
      const auto = !!(view.autoExposure && ae && !view.albedoOnly);
      gl.uniform1i(c.loc.uAuto, auto ? 1 : 0);
      gl.uniform4f(c.loc.uAE, ae ? ae.a : 0, ae ? ae.b : 0, ae ? ae.light_range[0] : 1, ae ? ae.light_range[1] : 1);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }

    // The model's learnt auto-exposure, or null (the paper's Psi holds each frame's own gain).
    autoExposure() {
      const sh = this.meta.shading;
      return sh.kind === "calibrated" ? sh.auto_exposure : null;
    }
  }

  Renderer.psiWeights = psiWeights;
  return Renderer;
})();
