// How close a stock three.js render of a model's airway.glb comes to `bronchosim render`
// (issue 19, BENCHMARKS.md): three.js's GLTFLoader loads the mesh, its texture and the
// KHR_lights_punctual spot light on the "bronchoscope" node; the node is moved to each view's
// pose (the light moves with the camera, as the scope's does), the camera gets the view's
// intrinsics, and the frame is rendered with no tone mapping and sRGB output. PSNR over every
// pixel of the 8-bit sRGB images, and after one least-squares gain per channel (as `bronchosim
// evaluate` scores).
//
//   npm install --prefix bench/three_glb
//   node bench/three_glb/compare.mjs MODEL VIEWS_JSON CAMERA_JSON RENDERED_DIR
// e.g. after `bronchosim demo`:
//   node bench/three_glb/compare.mjs bronchosim-demo/model bronchosim-demo/case/truth/views.json \
//        bronchosim-demo/case/truth/camera.json bronchosim-demo/views
//
// Serves the files on 127.0.0.1 (ES modules do not load from file://) and drives the system's
// Chromium ($CHROMIUM or /usr/bin/chromium) headless with SwiftShader. Not run in CI.
import { chromium } from "playwright-core";
import fs from "node:fs";
import http from "node:http";
import os from "node:os";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const [model, viewsJson, cameraJson, rendered] = process.argv.slice(2);
if (!rendered) {
  console.error("usage: node compare.mjs MODEL VIEWS_JSON CAMERA_JSON RENDERED_DIR");
  process.exit(2);
}
const views = JSON.parse(fs.readFileSync(viewsJson, "utf8")).frames;
const cam = JSON.parse(fs.readFileSync(cameraJson, "utf8"));

const page = `<!DOCTYPE html><html><body style="margin:0"><canvas id="c"></canvas>
<script type="importmap">{"imports":{"three":"/three/build/three.module.js","three/addons/":"/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
const cam = ${JSON.stringify(cam)};
const canvas = document.getElementById("c");
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.setSize(cam.width, cam.height, false);
renderer.outputColorSpace = THREE.SRGBColorSpace;
renderer.toneMapping = THREE.NoToneMapping;
const gltf = await new GLTFLoader().loadAsync("/model/airway.glb");
const scene = gltf.scene;
const scope = scene.getObjectByName("bronchoscope");
const light = scope && scope.children.find((c) => c.isSpotLight);
const camera = new THREE.PerspectiveCamera();
const near = 0.1, far = 2000;
// OpenCV intrinsics to a three.js projection (pixel centres at integers).
const P = new THREE.Matrix4().set(
  2 * cam.fx / cam.width, 0, 1 - 2 * (cam.cx + 0.5) / cam.width, 0,
  0, 2 * cam.fy / cam.height, 2 * (cam.cy + 0.5) / cam.height - 1, 0,
  0, 0, -(far + near) / (far - near), -2 * far * near / (far - near),
  0, 0, -1, 0);
camera.projectionMatrix.copy(P);
camera.projectionMatrixInverse.copy(P).invert();
const ref2d = document.createElement("canvas").getContext("2d", { willReadFrequently: true });
async function pixels(url) {
  const img = new Image();
  img.src = url;
  await img.decode();
  ref2d.canvas.width = img.width; ref2d.canvas.height = img.height;
  ref2d.drawImage(img, 0, 0);
  return ref2d.getImageData(0, 0, img.width, img.height).data;
}
window.renderView = async (c2w, refUrl) => {
  // OpenCV camera -> world to a three.js (glTF) camera: flip y and z.
  const m = new THREE.Matrix4().set(...c2w).multiply(new THREE.Matrix4().makeScale(1, -1, -1));
  for (const o of [camera, scope]) {
    o.matrixAutoUpdate = false;
    o.matrix.copy(m);
    o.matrixWorldNeedsUpdate = true;
  }
  scene.updateMatrixWorld(true);
  camera.matrixWorldInverse.copy(camera.matrixWorld).invert();
  renderer.render(scene, camera);
  const mine = await pixels(canvas.toDataURL("image/png"));
  const ref = await pixels(refUrl);
  let se = 0, n = 0;
  const xy = [[0, 0, 0], [0, 0, 0]];
  for (let i = 0; i < ref.length; i += 4) {
    for (let c = 0; c < 3; c++) {
      const d = mine[i + c] - ref[i + c];
      se += d * d; n++;
      xy[0][c] += mine[i + c] * ref[i + c]; xy[1][c] += mine[i + c] * mine[i + c];
    }
  }
  // After one least-squares gain per channel on the 8-bit values.
  const g = [0, 1, 2].map((c) => xy[1][c] > 0 ? xy[0][c] / xy[1][c] : 1);
  let se2 = 0;
  for (let i = 0; i < ref.length; i += 4) for (let c = 0; c < 3; c++) {
    const d = Math.min(255, g[c] * mine[i + c]) - ref[i + c]; se2 += d * d;
  }
  const psnr = (s) => 10 * Math.log10(255 * 255 / Math.max(s / n, 1e-12));
  return { psnr: psnr(se), psnrGain: psnr(se2), gain: g, png: canvas.toDataURL("image/png") };
};
window.sceneInfo = { light: light ? { intensity: light.intensity, color: light.color.toArray(), angle: light.angle, penumbra: light.penumbra, decay: light.decay } : null };
document.title = "ready";
</script></body></html>`;

const roots = { "/three/": path.join(here, "node_modules/three/"), "/model/": path.resolve(model) + "/", "/rendered/": path.resolve(rendered) + "/" };
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(req.url.split("?")[0]);
  if (url === "/") { res.writeHead(200, { "content-type": "text/html" }); res.end(page); return; }
  const root = Object.keys(roots).find((r) => url.startsWith(r));
  const file = root && path.join(roots[root], url.slice(root.length));
  if (!file || !file.startsWith(roots[root]) || !fs.existsSync(file)) { res.writeHead(404); res.end(); return; }
  const type = file.endsWith(".js") ? "text/javascript" : file.endsWith(".png") ? "image/png" : "application/octet-stream";
  res.writeHead(200, { "content-type": type });
  fs.createReadStream(file).pipe(res);
});
await new Promise((r) => server.listen(0, "127.0.0.1", r));
const port = server.address().port;
const profile = fs.mkdtempSync(path.join(os.tmpdir(), "bronchosim-three-"));
const ctx = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", "--force-color-profile=srgb"],
  viewport: { width: cam.width, height: cam.height },
});
try {
  const p = await ctx.newPage();
  p.on("console", (m) => { if (m.type() === "error") console.error("page:", m.text()); });
  await p.goto(`http://127.0.0.1:${port}/`);
  await p.waitForFunction(() => document.title === "ready", null, { timeout: 120000 });
  const out = { light: await p.evaluate(() => window.sceneInfo.light), views: [] };
  const outDir = fs.mkdtempSync(path.join(os.tmpdir(), "three-glb-views-"));
  for (const v of views) {
    const r = await p.evaluate(([m, u]) => window.renderView(m, u), [v.camera_to_world, `/rendered/${v.image}`]);
    const file = path.join(outDir, path.basename(v.image));
    fs.writeFileSync(file, Buffer.from(r.png.split(",")[1], "base64"));
    out.views.push({ image: v.image, psnr_db: r.psnr, psnr_after_gain_db: r.psnrGain, gain: r.gain, file });
  }
  const mean = (k) => out.views.reduce((s, v) => s + v[k], 0) / out.views.length;
  out.mean_psnr_db = mean("psnr_db");
  out.mean_psnr_after_gain_db = mean("psnr_after_gain_db");
  console.log(JSON.stringify(out, null, 1));
} finally {
  await ctx.close();
  server.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
