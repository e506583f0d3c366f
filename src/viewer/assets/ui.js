// bronchosim viewer: the control panel (autopilot, speed, field of view, exposure, screenshot,
// the current pose in poses.json form). It only reads and sets the state main.js keeps.
"use strict";
window.BS = window.BS || {};

BS.UI = (function () {
  const M = BS.math;
  const $ = (id) => document.getElementById(id);

  class UI {
    constructor(app) {
      this.app = app;
      const nav = app.nav;
      $("model-name").textContent = app.model.meta.model_name + " · " + app.model.meta.shading.kind + " shading";
      $("play").addEventListener("click", () => {
        if (nav.atPathEnd()) nav.setPathPos(0, true);
        nav.playing = !nav.playing;
        app.invalidate();
      });
      $("path").addEventListener("input", (e) => {
        nav.playing = false;
        nav.setPathPos(Number(e.target.value) / 1000, true);
      });
      $("speed").addEventListener("input", (e) => {
        nav.speed = Math.pow(10, Number(e.target.value));
        nav.autopilotSpeed = nav.speed;
        app.invalidate();
      });
      $("fov").addEventListener("input", (e) => { app.fovDeg = Number(e.target.value); app.invalidate(); });
      $("ev").addEventListener("input", (e) => { app.ev = Number(e.target.value); app.invalidate(); });
      const auto = $("auto");
      auto.disabled = !app.renderer.autoExposure();
      auto.checked = app.autoExposure;
      auto.addEventListener("change", (e) => { app.autoExposure = e.target.checked; app.invalidate(); });
      $("albedo").addEventListener("change", (e) => { app.albedoOnly = e.target.checked; app.invalidate(); });
      $("unseen").disabled = !app.renderer.texCoverage;
      $("unseen").addEventListener("change", (e) => { app.markUnseen = e.target.checked; app.invalidate(); });
      $("shot").addEventListener("click", () => app.screenshot());
      $("copy-pose").addEventListener("click", () => this.copy($("pose").value, "copy-pose"));
      $("copy-link").addEventListener("click", () => this.copy(location.href.split("#")[0] + M.formatHash(nav.pose, app.camera()), "copy-link"));
      window.addEventListener("keydown", (e) => {
        if (e.key === "h" && !/INPUT|TEXTAREA/.test(e.target.tagName)) $("panel").classList.toggle("hidden");
        if (e.key === " " && !/INPUT|TEXTAREA|BUTTON/.test(e.target.tagName)) { e.preventDefault(); $("play").click(); }
      });
      $("panel").classList.remove("hidden");
    }

    copy(text, button) {
      const done = () => { const b = $(button); const t = b.textContent; b.textContent = "copied"; setTimeout(() => { b.textContent = t; }, 900); };
      if (navigator.clipboard && window.isSecureContext) {
        navigator.clipboard.writeText(text).then(done, () => this.copyBySelection(text, done));
      } else {
        this.copyBySelection(text, done);
      }
    }

    copyBySelection(text, done) {
      const ta = document.createElement("textarea");
      ta.value = text;
      document.body.appendChild(ta);
      ta.select();
      try { document.execCommand("copy"); done(); } finally { ta.remove(); }
    }

    // Refresh what the panel shows (called after each drawn frame, at most a few times a second).
    update(stats) {
      const app = this.app, nav = app.nav;
      $("play").textContent = nav.playing ? "Pause" : "Play";
      if (document.activeElement !== $("path")) $("path").value = String(Math.round(nav.pathPos * 1000));
      $("speed-value").textContent = nav.speed.toFixed(1) + " mm/s";
      $("speed").value = String(Math.log10(nav.speed));
      $("fov-value").textContent = app.fovDeg.toFixed(0) + "°";
      $("ev-value").textContent = (app.ev >= 0 ? "+" : "") + app.ev.toFixed(1) + " EV";
      const wall = nav.distance(M.axes(nav.pose).t);
      $("stats").textContent = stats.fps.toFixed(1) + " fps · " + stats.width + "×" + stats.height + " · wall " + wall.toFixed(1) + " mm";
      const text = M.posesJson(nav.pose, "view.png");
      if ($("pose").value !== text) $("pose").value = text;
    }
  }

  return UI;
})();
