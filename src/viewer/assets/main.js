// bronchosim viewer: start-up and the frame loop.
// With `#...&camera=W,H,fx,fy,cx,cy` in the URL the page draws that one view on a W x H canvas
// at the top-left corner (one canvas pixel per CSS pixel, nothing drawn over it) and sets
// document.title to "ready" once it is on screen: what tests and scripts use. Without it the
// canvas fills the window and the controls are shown.
"use strict";
window.BS = window.BS || {};

(function () {
  const M = BS.math;
  const started = performance.now();

  function fail(message) {
    const el = document.getElementById("error");
    el.textContent = "bronchosim viewer: " + message;
    el.classList.remove("hidden");
    document.title = "error: " + message;
    console.error(message);
  }

  class App {
    constructor(model) {
      this.model = model;
      const hash = M.parseHash(location.hash);
      if (hash.errors.length) throw new Error("URL " + hash.errors.join("; "));
      this.fixedCamera = hash.camera;
      this.canvas = document.getElementById("view");
      this.renderer = new BS.Renderer(this.canvas, model);
      const distance = BS.decode.field(model.meta, model.field);
      this.nav = new BS.Navigation(model, distance, () => this.invalidate());
      if (hash.pose) this.nav.pose = hash.pose;
      const c = model.meta.camera;
      this.fovDeg = (2 * Math.atan(c.height / 2 / c.fy) * 180) / Math.PI;
      this.ev = 0;
      this.autoExposure = false;
      this.albedoOnly = false;
      this.markUnseen = false;
      this.dirty = true;
      this.frameTimes = [];
      this.framesDrawn = 0;
      this.lastUi = 0;
    }

    invalidate() { this.dirty = true; }

    // The camera the view is drawn with: the URL's, or a pinhole filling the window.
    camera() {
      if (this.fixedCamera) return this.fixedCamera;
      const dpr = Math.min(window.devicePixelRatio || 1, 2);
      const width = Math.max(1, Math.round(window.innerWidth * dpr));
      const height = Math.max(1, Math.round(window.innerHeight * dpr));
      const f = height / 2 / Math.tan((this.fovDeg * Math.PI) / 360);
      return { width, height, fx: f, fy: f, cx: (width - 1) / 2, cy: (height - 1) / 2 };
    }

    draw() {
      const cam = this.camera();
      if (this.canvas.width !== cam.width || this.canvas.height !== cam.height) {
        this.canvas.width = cam.width;
        this.canvas.height = cam.height;
      }
      if (this.fixedCamera) {
        this.canvas.style.width = cam.width + "px";
        this.canvas.style.height = cam.height + "px";
      } else {
        this.canvas.style.width = "100vw";
        this.canvas.style.height = "100vh";
      }
      this.renderer.draw({
        pose: this.nav.pose,
        camera: cam,
        gain: Math.pow(2, this.ev),
        autoExposure: this.autoExposure,
        albedoOnly: this.albedoOnly,
        markUnseen: this.markUnseen,
      });
      this.framesDrawn++;
      this.dirty = false;
    }

    screenshot() {
      this.draw();
      this.canvas.toBlob((blob) => {
        const a = document.createElement("a");
        a.href = URL.createObjectURL(blob);
        a.download = "bronchosim-view.png";
        a.click();
        setTimeout(() => URL.revokeObjectURL(a.href), 1000);
      }, "image/png");
    }

    // The interactive loop: advance the navigation, draw when something changed.
    run() {
      this.nav.attach(this.canvas);
      this.ui = new BS.UI(this);
      window.addEventListener("resize", () => this.invalidate());
      let last = performance.now();
      const frame = (now) => {
        // Real time, so that a slow renderer moves as far per second (capped after a pause).
        const dt = Math.min((now - last) / 1000, 0.5);
        last = now;
        this.nav.step(dt);
        if (this.dirty) {
          this.draw();
          this.frameTimes.push(now);
          while (this.frameTimes.length > 1 && now - this.frameTimes[0] > 1000) this.frameTimes.shift();
        }
        if (now - this.lastUi > 200) {
          const n = this.frameTimes.length;
          const fps = n > 1 ? ((n - 1) * 1000) / (this.frameTimes[n - 1] - this.frameTimes[0]) : 0;
          this.ui.update({ fps, width: this.canvas.width, height: this.canvas.height });
          this.lastUi = now;
        }
        requestAnimationFrame(frame);
      };
      requestAnimationFrame(frame);
    }
  }

  // Draw the URL's view; the title becomes "ready" once the frame has been composited.
  function drawFixed(app) {
    document.title = "drawing";
    app.draw();
    app.renderer.gl.finish();
    requestAnimationFrame(() => requestAnimationFrame(() => { document.title = "ready"; }));
  }

  async function start() {
    if (!window.BRONCHOSIM_MODEL) throw new Error("model-data.js is missing or did not load");
    const model = await BS.decode.model(window.BRONCHOSIM_MODEL);
    const app = new App(model);
    // For scripts and tests: the state, and a way to draw now.
    window.bronchosim = { app, nav: app.nav, renderer: app.renderer, loadMs: null };
    if (app.fixedCamera) {
      document.body.classList.add("fixed");
      drawFixed(app);
      window.bronchosim.loadMs = performance.now() - started;
      // A new hash on the same page draws the new view.
      window.addEventListener("hashchange", () => {
        try {
          const h = M.parseHash(location.hash);
          if (h.errors.length || !h.camera) throw new Error("URL " + (h.errors.join("; ") || "camera missing"));
          app.fixedCamera = h.camera;
          if (h.pose) app.nav.pose = h.pose;
          drawFixed(app);
        } catch (e) {
          fail(e.message || String(e));
        }
      });
      return;
    }
    app.run();
    requestAnimationFrame(() => {
      window.bronchosim.loadMs = performance.now() - started;
      document.title = "bronchosim · " + model.meta.model_name;
    });
  }

  window.addEventListener("load", () => start().catch((e) => fail(e.message || String(e))));
})();
