// bronchosim viewer: moving the camera. Mouse drag looks around, keys move (speed adjustable)
// and roll, the wheel moves along the view, and the autopilot follows the centre line. Every
// move is checked against the inside-distance field of the airway mask: the camera keeps at
// least `clearanceMm` from the wall, sliding along it rather than passing through.
"use strict";
window.BS = window.BS || {};

BS.Navigation = (function () {
  const M = BS.math;

  class Navigation {
    constructor(model, distance, onChange) {
      this.path = model.meta.path;
      this.pathLength = model.meta.path_length_mm;
      this.distance = distance;
      this.onChange = onChange;
      this.pose = this.path[0].slice();
      this.speed = 5;            // mm/s
      this.turnRate = 0.004;     // radians per pixel of mouse drag
      this.rollRate = 1.2;       // radians per second
      this.clearanceMm = 0.5;
      this.keys = new Map();     // key held -> time (ms) up to which its move is applied
      this.tapped = [];          // [key, seconds held] released since the last step
      this.playing = false;
      this.pathPos = 0;          // autopilot position along the path, 0..1
      this.autopilotSpeed = 5;   // mm/s
      this.blocked = 0;          // steps the wall stopped or deflected
    }

    setPose(p) { this.pose = p.slice(); this.onChange(); }

    // Move the centre by `d` (mm, world) in steps of at most 0.25 mm, never closer to the wall
    // than the clearance: a step into the wall keeps only its component along the wall (when
    // that is at least 30% of it: a camera flown head-on into the wall stops); a camera already
    // too close may still move away from the wall. Returns true when the camera moved.
    tryMove(d) {
      const n = Math.max(1, Math.ceil(M.norm(d) / 0.25));
      const step = M.scale(d, 1 / n);
      let moved = false;
      for (let i = 0; i < n; i++) {
        if (!this.tryStep(step)) break;
        moved = true;
      }
      return moved;
    }

    tryStep(d) {
      const A = M.axes(this.pose);
      const here = this.distance(A.t);
      const ok = (p) => { const dp = this.distance(p); return dp >= this.clearanceMm || dp > here + 1e-6; };
      let target = M.add(A.t, d);
      if (!ok(target)) {
        this.blocked++;
        const g = this.gradient(target);
        const into = M.dot(d, g);
        const slide = into < 0 ? M.sub(d, M.scale(g, into)) : d;
        if (M.norm(slide) < 0.3 * M.norm(d)) return false;
        target = M.add(A.t, slide);
        if (!ok(target)) return false;
      }
      this.pose = M.moved(this.pose, target);
      return true;
    }

    // Unit gradient of the distance field at p (points away from the wall).
    gradient(p) {
      const h = 0.25;
      const g = [0, 1, 2].map((k) => {
        const a = p.slice(), b = p.slice();
        a[k] += h; b[k] -= h;
        return (this.distance(a) - this.distance(b)) / (2 * h);
      });
      return M.normalize(g);
    }

    // Seconds each movement key was held since the last step (keys are timed by their events,
    // not sampled per frame, so that a slow renderer or a short tap moves the right distance).
    heldSeconds(now) {
      const secs = new Map();
      const add = (k, t) => secs.set(k, (secs.get(k) || 0) + Math.max(t, 0));
      for (const [k, t] of this.tapped) add(k, t);
      this.tapped = [];
      for (const [k, since] of this.keys) { add(k, (now - since) / 1000); this.keys.set(k, now); }
      return secs;
    }

    // Advance by dt seconds (the autopilot) and apply the keys held since the last step.
    step(dt) {
      let changed = false;
      if (this.playing) {
        const len = Math.max(this.pathLength, 1e-6);
        this.setPathPos(this.pathPos + (this.autopilotSpeed * dt) / len, false);
        if (this.pathPos >= 1) this.playing = false;
        changed = true;
      }
      if (this.keys.size || this.tapped.length) {
        const fast = this.keys.has("Shift") ? 4 : 1;
        const secs = this.heldSeconds(performance.now());
        const t = (...names) => names.reduce((s, n) => s + (secs.get(n) || 0), 0);
        const A = M.axes(this.pose);
        const v = this.speed * fast;
        let d = [0, 0, 0];
        const along = (axis, s) => { d = M.add(d, M.scale(axis, s * v)); };
        along(A.z, t("w", "ArrowUp") - t("s", "ArrowDown"));
        along(A.x, t("d", "ArrowRight") - t("a", "ArrowLeft"));
        along(A.y, t("f", "PageDown") - t("r", "PageUp"));
        if (M.norm(d) > 0) { this.playing = false; changed = this.tryMove(d) || changed; }
        const roll = t("e") - t("q");
        if (roll) { this.pose = M.turn(this.pose, "z", this.rollRate * roll); changed = true; }
      }
      if (changed) this.onChange();
      return changed;
    }

    // Mouse drag by (dx, dy) pixels: right turns right (about the image's down axis), up looks up.
    look(dx, dy) {
      this.pose = M.turn(M.turn(this.pose, "y", dx * this.turnRate), "x", -dy * this.turnRate);
      this.onChange();
    }

    // Autopilot position (0..1 along the path); `user` = set from the slider (pauses nothing).
    setPathPos(f, user) {
      const n = this.path.length;
      this.pathPos = Math.min(Math.max(f, 0), 1);
      const x = this.pathPos * (n - 1);
      const i = Math.min(Math.floor(x), n - 2);
      this.pose = n > 1 ? M.blend(this.path[i], this.path[i + 1], x - i) : this.path[0].slice();
      if (user) this.onChange();
    }

    atPathEnd() { return this.pathPos >= 1; }

    // Keyboard and mouse on `el` (the canvas) and the window.
    attach(el) {
      const keyName = (e) => (e.key.length === 1 ? e.key.toLowerCase() : e.key);
      const editing = (e) => /INPUT|TEXTAREA|SELECT/.test((e.target && e.target.tagName) || "");
      window.addEventListener("keydown", (e) => {
        if (editing(e)) return;
        if (e.key === "+" || e.key === "=") { this.speed = Math.min(this.speed * 1.25, 200); this.onChange(); return; }
        if (e.key === "-" || e.key === "_") { this.speed = Math.max(this.speed / 1.25, 0.1); this.onChange(); return; }
        const k = keyName(e);
        if (!this.keys.has(k)) this.keys.set(k, performance.now());
        if (/^(Arrow|Page)/.test(e.key)) e.preventDefault();
      });
      window.addEventListener("keyup", (e) => {
        const k = keyName(e);
        if (this.keys.has(k)) this.tapped.push([k, (performance.now() - this.keys.get(k)) / 1000]);
        this.keys.delete(k);
      });
      window.addEventListener("blur", () => this.keys.clear());
      let last = null;
      el.addEventListener("mousedown", (e) => { last = [e.clientX, e.clientY]; e.preventDefault(); });
      window.addEventListener("mouseup", () => { last = null; });
      window.addEventListener("mousemove", (e) => {
        if (!last || !(e.buttons & 1)) { last = null; return; }
        const dx = e.clientX - last[0], dy = e.clientY - last[1];
        last = [e.clientX, e.clientY];
        if (dx || dy) { this.playing = false; this.look(dx, dy); }
      });
      el.addEventListener("wheel", (e) => {
        e.preventDefault();
        this.playing = false;
        const A = M.axes(this.pose);
        if (this.tryMove(M.scale(A.z, -Math.sign(e.deltaY) * this.speed * 0.1))) this.onChange();
      }, { passive: false });
    }
  }

  return Navigation;
})();
