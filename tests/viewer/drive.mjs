// Drives a bronchosim viewer folder in the system's headless Chromium (playwright-core, pinned
// in package.json). Used by tests/viewer.rs and to measure the viewer for BENCHMARKS.md.
//
//   node drive.mjs shots VIEWER VIEWS_JSON CAMERA_JSON OUT_DIR
//       every view of VIEWS_JSON through the URL hash (#pose=...&camera=...), one screenshot
//       per view into OUT_DIR (named as the view's "image"); prints {"views": [...]} as JSON
//   node drive.mjs navigate VIEWER
//       scripted keys, mouse, a flight into the wall and the autopilot; prints the numbers
//   node drive.mjs fps VIEWER [WIDTHxHEIGHT] [SECONDS]
//       frame rate of an autopilot flight (requestAnimationFrame) and the loading time
//
// Chromium: $CHROMIUM or /usr/bin/chromium, with SwiftShader WebGL (no GPU needed).
import { chromium } from "playwright-core";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { pathToFileURL } from "node:url";

const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const ARGS = [
  "--no-sandbox",
  "--use-angle=swiftshader",
  "--enable-unsafe-swiftshader",
  "--ignore-gpu-blocklist",
  "--disable-background-networking",
  "--disable-component-update",
  "--no-first-run",
  "--force-color-profile=srgb",
];

async function withBrowser(fn) {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), "bronchosim-chromium-"));
  const ctx = await chromium.launchPersistentContext(profile, {
    executablePath,
    headless: true,
    args: ARGS,
    viewport: { width: 800, height: 600 },
    deviceScaleFactor: 1,
  });
  try {
    return await fn(ctx);
  } finally {
    await ctx.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
}

const indexUrl = (viewer) => pathToFileURL(path.resolve(viewer, "index.html")).href;

// Wait until the page says "ready" (or fails).
async function waitReady(page, what) {
  await page.waitForFunction(() => document.title === "ready" || document.title.startsWith("error"), null, { timeout: 120000 });
  const title = await page.title();
  if (title !== "ready") throw new Error(`${what}: ${title}`);
}

async function shots(viewer, viewsJson, cameraJson, outDir) {
  const views = JSON.parse(fs.readFileSync(viewsJson, "utf8")).frames;
  const cam = JSON.parse(fs.readFileSync(cameraJson, "utf8"));
  const camera = [cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy].join(",");
  fs.mkdirSync(outDir, { recursive: true });
  const out = [];
  await withBrowser(async (ctx) => {
    const page = await ctx.newPage();
    page.on("console", (m) => { if (m.type() === "error") console.error("page:", m.text()); });
    await page.setViewportSize({ width: cam.width, height: cam.height });
    for (const v of views) {
      const url = indexUrl(viewer) + "#pose=" + v.camera_to_world.join(",") + "&camera=" + camera;
      const t0 = Date.now();
      await page.goto("about:blank");
      await page.goto(url);
      await waitReady(page, v.image);
      const file = path.join(outDir, v.image);
      fs.mkdirSync(path.dirname(file), { recursive: true });
      await page.screenshot({ path: file, clip: { x: 0, y: 0, width: cam.width, height: cam.height } });
      const info = await page.evaluate(() => ({
        canvas: [document.getElementById("view").width, document.getElementById("view").height],
        css: [document.getElementById("view").clientWidth, document.getElementById("view").clientHeight],
        panelShown: getComputedStyle(document.getElementById("panel")).display !== "none",
      }));
      out.push({ image: v.image, ms: Date.now() - t0, ...info });
    }
  });
  return { views: out };
}

async function openInteractive(ctx, viewer, width, height) {
  const page = await ctx.newPage();
  page.on("console", (m) => { if (m.type() === "error") console.error("page:", m.text()); });
  await page.setViewportSize({ width, height });
  const t0 = Date.now();
  await page.goto(indexUrl(viewer));
  await page.waitForFunction(() => window.bronchosim && window.bronchosim.loadMs !== null || document.title.startsWith("error"), null, { timeout: 120000 });
  const title = await page.title();
  if (title.startsWith("error")) throw new Error(title);
  const loadMs = await page.evaluate(() => window.bronchosim.loadMs);
  return { page, loadMs, wallMs: Date.now() - t0 };
}

const state = (page) => page.evaluate(() => {
  const n = window.bronchosim.nav;
  const a = BS.math.axes(n.pose);
  return { pose: n.pose, centre: a.t, forward: a.z, down: a.y, wall: n.distance(a.t), blocked: n.blocked, pathPos: n.pathPos, playing: n.playing, clearance: n.clearanceMm, drawn: window.bronchosim.app.framesDrawn };
});

// Hold `key` for `ms` milliseconds, then wait until the viewer has applied all of it.
async function hold(page, key, ms) {
  await page.keyboard.down(key);
  await page.waitForTimeout(ms);
  await page.keyboard.up(key);
  await page.waitForFunction(() => window.bronchosim.nav.keys.size === 0 && window.bronchosim.nav.tapped.length === 0);
}

async function navigate(viewer) {
  return withBrowser(async (ctx) => {
    const { page, loadMs } = await openInteractive(ctx, viewer, 640, 480);
    const r = { loadMs };
    const s0 = await state(page);
    r.start = s0;
    // "mark unseen walls": blue over red of the drawn image, off, on, off again.
    r.unseen = await page.evaluate(() => {
      const app = window.bronchosim.app, c = document.getElementById("view"), box = document.getElementById("unseen");
      const blueOverRed = () => {
        app.draw();
        const t = document.createElement("canvas");
        t.width = c.width; t.height = c.height;
        const g = t.getContext("2d");
        g.drawImage(c, 0, 0);
        const d = g.getImageData(0, 0, t.width, t.height).data;
        let red = 0, blue = 0;
        for (let i = 0; i < d.length; i += 4) { red += d[i]; blue += d[i + 2]; }
        return blue / Math.max(red, 1);
      };
      const off = blueOverRed();
      box.click();
      const on = blueOverRed();
      box.click();
      return { enabled: !box.disabled, off, on, offAgain: blueOverRed() };
    });
    // Keys: hold W for 0.5 s at the default speed: the camera moves forward.
    await page.focus("#view");
    await hold(page, "w", 500);
    const s1 = await state(page);
    r.forwardMoveMm = Math.hypot(...s1.centre.map((v, i) => v - s0.centre[i]));
    r.forwardAlongView = s1.centre.map((v, i) => v - s0.centre[i]).reduce((s, d, i) => s + d * s0.forward[i], 0);
    // Mouse: drag 100 px to the right on the canvas left of the control panel: the view turns
    // right (forward gains a component along the old right axis), the centre stays.
    const s1Right = await page.evaluate(() => BS.math.axes(window.bronchosim.nav.pose).x);
    await page.mouse.move(40, 240);
    await page.mouse.down();
    await page.mouse.move(90, 240, { steps: 5 });
    await page.mouse.move(140, 240, { steps: 5 });
    await page.mouse.up();
    const s2 = await state(page);
    r.turnDeg = (Math.acos(Math.min(1, s2.forward.reduce((s, d, i) => s + d * s1.forward[i], 0))) * 180) / Math.PI;
    r.turnedRight = s2.forward.reduce((s, d, i) => s + d * s1Right[i], 0) > 0;
    r.lookMovedCentre = Math.hypot(...s2.centre.map((v, i) => v - s1.centre[i]));
    // Roll: hold E for 0.3 s: down rotates about forward.
    await hold(page, "e", 300);
    const s3 = await state(page);
    r.rollDeg = (Math.acos(Math.min(1, s3.down.reduce((s, d, i) => s + d * s2.down[i], 0))) * 180) / Math.PI;
    // The wall: turn to face the nearest wall and fly at it fast for 3 s.
    await page.evaluate(() => {
      const n = window.bronchosim.nav, M = BS.math;
      const a = M.axes(n.pose);
      const g = n.gradient(a.t);                      // away from the wall
      n.setPose(M.fromAxes(M.scale(g, -1), a.y, a.t)); // face the wall
      n.speed = 40;
    });
    const sWall0 = await state(page);
    await hold(page, "w", 3000);
    const sWall = await state(page);
    r.wall = { before: sWall0.wall, after: sWall.wall, clearance: sWall.clearance, blocked: sWall.blocked - sWall0.blocked, moved: Math.hypot(...sWall.centre.map((v, i) => v - sWall0.centre[i])) };
    // Sample the straight line from the wall position 2 mm further along the view: it must
    // leave the lumen (else "stopped by the wall" would mean nothing).
    r.wall.beyond = await page.evaluate(() => {
      const n = window.bronchosim.nav, M = BS.math, a = M.axes(n.pose);
      return n.distance(M.add(a.t, M.scale(a.z, 2)));
    });
    // The autopilot: from the start of the path, fast, until it stops.
    await page.evaluate(() => {
      const n = window.bronchosim.nav;
      n.setPathPos(0, true);
      n.autopilotSpeed = 60;
    });
    await page.click("#play");
    const t0 = Date.now();
    await page.waitForFunction(() => !window.bronchosim.nav.playing, null, { timeout: 120000 });
    const sEnd = await state(page);
    const last = await page.evaluate(() => window.bronchosim.nav.path[window.bronchosim.nav.path.length - 1]);
    r.autopilot = { seconds: (Date.now() - t0) / 1000, pathPos: sEnd.pathPos, endOffMm: Math.hypot(last[3] - sEnd.centre[0], last[7] - sEnd.centre[1], last[11] - sEnd.centre[2]), drawn: sEnd.drawn - sWall.drawn };
    // The pose box reads back the current pose in poses.json form (refreshed every 200 ms).
    await page.waitForTimeout(400);
    const box = await page.evaluate(() => JSON.parse(document.getElementById("pose").value));
    r.poseBoxOffMm = Math.hypot(box.frames[0].camera_to_world[3] - sEnd.centre[0], box.frames[0].camera_to_world[7] - sEnd.centre[1], box.frames[0].camera_to_world[11] - sEnd.centre[2]);
    return r;
  });
}

async function fps(viewer, size, seconds) {
  const [width, height] = size.split("x").map(Number);
  return withBrowser(async (ctx) => {
    const { page, loadMs, wallMs } = await openInteractive(ctx, viewer, width, height);
    const r = await page.evaluate(async (secs) => {
      const n = window.bronchosim.nav, app = window.bronchosim.app;
      n.setPathPos(0, true);
      n.autopilotSpeed = Math.max(n.pathLength / secs, 1);
      n.playing = true;
      const d0 = app.framesDrawn, t0 = performance.now();
      await new Promise((res) => setTimeout(res, secs * 1000));
      const frames = app.framesDrawn - d0, ms = performance.now() - t0;
      n.playing = false;
      return { frames, seconds: ms / 1000, fps: (frames * 1000) / ms, canvas: [app.canvas.width, app.canvas.height] };
    }, seconds);
    return { loadMs, pageLoadWallMs: wallMs, ...r };
  });
}

const [cmd, ...a] = process.argv.slice(2);
const run = { shots: () => shots(a[0], a[1], a[2], a[3]), navigate: () => navigate(a[0]), fps: () => fps(a[0], a[1] || "1280x720", Number(a[2] || 10)) }[cmd];
if (!run) {
  console.error("usage: node drive.mjs shots|navigate|fps VIEWER ...");
  process.exit(2);
}
run().then((r) => console.log(JSON.stringify(r)), (e) => { console.error(String(e && e.stack || e)); process.exit(1); });
