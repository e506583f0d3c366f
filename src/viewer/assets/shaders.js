// bronchosim viewer: the GLSL of the three passes.
// 1. surface: per pixel, exactly `bronchosim render`'s shading (src/render/novel_view.rs) at
//    the reference gain: shading(gamma, z, theta) x albedo (trilinear, level from the footprint)
//    + the ambient term; alpha marks the pixels that see the surface;
// 2. reduce: sums of luminance and of surface pixels over 4x4 blocks, down to one texel;
// 3. composite: + kappa x the view's mean luminance (inter-reflection), x gain (fixed or the
//    learnt auto-exposure), sRGB.
"use strict";
window.BS = window.BS || {};

BS.shaders = (function () {
  const header = "#version 300 es\nprecision highp float;\nprecision highp int;\nprecision highp sampler2D;\n";
  const LUMA = "const vec3 LUMA = vec3(0.2126, 0.7152, 0.0722);\n";

  // Camera coordinates -> clip space for a pinhole camera whose pixel centres sit at integer
  // image coordinates (OpenCV), image row 0 at the top of the viewport.
  const surfaceVS = header + `
layout(location = 0) in vec3 aPos;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec2 aUv;
uniform vec3 uOrigin;
uniform mat3 uWorldToCam;
uniform vec4 uIntr;   // fx, fy, cx, cy (pixels)
uniform vec2 uSize;   // width, height (pixels)
uniform vec2 uDepth;  // near, far (mm)
out vec3 vRel;
out vec3 vNormal;
out vec2 vUv;
invariant gl_Position;
void main() {
  vRel = aPos - uOrigin;
  vNormal = aNormal;
  vUv = aUv;
  vec3 c = uWorldToCam * vRel;
  float n = uDepth.x, f = uDepth.y;
  gl_Position = vec4(
    2.0 * (uIntr.x * c.x + (uIntr.z + 0.5) * c.z) / uSize.x - c.z,
    c.z - 2.0 * (uIntr.y * c.y + (uIntr.w + 0.5) * c.z) / uSize.y,
    c.z * (f + n) / (f - n) - 2.0 * f * n / (f - n),
    c.z);
}`;

  // The light's Bernstein polynomials as code: de Casteljau with the coefficients inlined
  // (uniform arrays indexed in loops are several times slower on software renderers).
  function casteljau(name, coeffs) {
    const c = coeffs.length ? coeffs : [0];
    const lines = c.map((v, i) => `  float b${i} = ${Number(v).toExponential(17)};`);
    for (let k = c.length - 1; k >= 1; k--) {
      for (let i = 0; i < k; i++) lines.push(`  b${i} = b${i} * (1.0 - t) + b${i + 1} * t;`);
    }
    return `float ${name}(float t) {\n${lines.join("\n")}\n  return b0;\n}\n`;
  }

  function lightFunctions(shading) {
    if (shading.kind !== "calibrated") return casteljau("lightS", [1]) + [0, 1, 2].map((c) => casteljau("rho" + c, [0])).join("");
    return casteljau("lightS", shading.s) + shading.rho.map((r, c) => casteljau("rho" + c, r)).join("");
  }

  const surfaceTemplate = header + `
in vec3 vRel;
in vec3 vNormal;
in vec2 vUv;
uniform mat3 uCamToWorld;
uniform vec4 uIntr;
uniform vec2 uSize;
uniform sampler2D uTex0;       // level 0, premultiplied RGBA
uniform sampler2D uTexMips;    // levels 1.. side by side
uniform ivec2 uLevelSize[8];
uniform ivec2 uLevelOffset[8];
uniform int uLevels;
uniform vec2 uAtlasSize;
uniform float uTexelMm;
uniform int uKind;             // 0 calibrated light, 1 the paper's Psi
uniform int uAlbedoOnly;
uniform sampler2D uCoverage;   // 1 where a frame saw the texel
uniform int uMarkUnseen;       // tint the walls no frame saw (synthesised or filled)
uniform float uCosEdge;
uniform vec3 uAmbient;
uniform vec3 uSpecK;           // the specular term's colour (0: none)
uniform float uSpecAlpha;      // its GGX roughness
uniform int uPsiCount;         // blended viewpoints (<= 4)
uniform vec4 uPsiC[12];        // c_0..c_3 of viewpoint k, channel c at [3 k + c]
uniform vec3 uPsiD[12];        // d_1..d_3
uniform vec2 uPsiZ[4];         // z_min, z_max
uniform float uPsiW[4];        // weights
out vec4 outColor;

LIGHT_FUNCTIONS

vec3 imageRay(vec2 px) {
  return normalize(vec3((px.x - uIntr.z) / uIntr.x, (px.y - uIntr.w) / uIntr.y, 1.0));
}

float angleBetween(vec3 a, vec3 b) { return 2.0 * asin(min(length(a - b) * 0.5, 1.0)); }

vec4 texel(int l, ivec2 p) {
  if (l == 0) return texelFetch(uTex0, p, 0);
  return texelFetch(uTexMips, uLevelOffset[l] + p, 0);
}

// Bilinear in level l with edge texels clamped; level-l coordinates are level-0 ones / 2^l.
vec4 bilinear(int l, vec2 uv) {
  ivec2 sz = uLevelSize[l];
  float s = 1.0 / float(1 << l);
  float x = clamp(uv.x * uAtlasSize.x * s - 0.5, 0.0, float(sz.x - 1));
  float y = clamp(uv.y * uAtlasSize.y * s - 0.5, 0.0, float(sz.y - 1));
  int x0 = int(x), y0 = int(y);
  int x1 = min(x0 + 1, sz.x - 1), y1 = min(y0 + 1, sz.y - 1);
  float fx = x - float(x0), fy = y - float(y0);
  vec4 top = mix(texel(l, ivec2(x0, y0)), texel(l, ivec2(x1, y0)), fx);
  vec4 bot = mix(texel(l, ivec2(x0, y1)), texel(l, ivec2(x1, y1)), fx);
  return mix(top, bot, fy);
}

vec3 albedo(vec2 uv, float lod) {
  float top = float(uLevels - 1);
  lod = clamp(lod, 0.0, top);
  int l0 = int(floor(lod));
  float f = lod - float(l0);
  vec4 a = bilinear(l0, uv);
  if (f > 0.0 && l0 + 1 < uLevels) a = a + f * (bilinear(l0 + 1, uv) - a);
  return a.w <= 1e-6 ? vec3(0.0) : a.rgb / a.w;
}

// GGX lobe with the light at the lens, D G1^2 / (4 gamma), 1 at gamma = 1 (lobe in specular.rs).
float ggxLobe(float a, float gamma) {
  float g = clamp(gamma, 1e-4, 1.0);
  float a2 = a * a;
  float den = g * g * (a2 - 1.0) + 1.0;
  float g1 = 2.0 * g / (g + sqrt(a2 + (1.0 - a2) * g * g));
  return a2 * a2 / (den * den) * g1 * g1 / g;
}

void main() {
  vec2 px = vec2(gl_FragCoord.x - 0.5, uSize.y - gl_FragCoord.y - 0.5);
  vec3 ray = imageRay(px);
  vec3 dir = uCamToWorld * ray;
  vec3 n = normalize(vNormal);
  float gamma = min(abs(dot(n, dir)), 1.0);
  float z = length(vRel);
  float pixelAngle = max(angleBetween(ray, imageRay(px + vec2(1.0, 0.0))),
                         angleBetween(ray, imageRay(px + vec2(0.0, 1.0))));
  float fp = z * pixelAngle / max(gamma, 1e-3);
  float lod = log2(max(fp / uTexelMm, 1.0));
  vec3 a = albedo(vUv, lod);
  if (uMarkUnseen == 1) {
    // Blue with the texture's own luminance, so the made-up pattern stays visible.
    float l = dot(a, vec3(0.2126, 0.7152, 0.0722));
    a = mix(a, l * vec3(0.5, 0.9, 2.4), 0.75 * (1.0 - texture(uCoverage, vUv).r));
  }
  if (uAlbedoOnly == 1) { outColor = vec4(a, 1.0); return; }
  vec3 scale = vec3(0.0);
  vec3 offset = vec3(0.0);
  if (uKind == 0) {
    float t = clamp((1.0 - ray.z) / (1.0 - uCosEdge), 0.0, 1.0);
    float light = lightS(t) / (z * z);
    scale = light * vec3(rho0(gamma), rho1(gamma), rho2(gamma));
    // The highlight: the light's colour, not the albedo's (shading::calibrated::specular).
    offset = uAmbient + light * uSpecK * ggxLobe(uSpecAlpha, gamma);
  } else {
    float s = 1.0 - gamma;
    vec4 bg = vec4(s * s * s, 3.0 * s * s * gamma, 3.0 * s * gamma * gamma, gamma * gamma * gamma);
    for (int v = 0; v < 4; v++) {
      if (v >= uPsiCount) break;
      float span = uPsiZ[v].y - uPsiZ[v].x;
      float r = span > 0.0 ? clamp((z - uPsiZ[v].x) / span, 0.0, 1.0) : 0.0;
      float q = 1.0 - r;
      vec4 br = vec4(q * q * q, 3.0 * q * q * r, 3.0 * q * r * r, r * r * r);
      for (int c = 0; c < 3; c++) {
        float rho = dot(uPsiC[3 * v + c], bg);
        float varrho = br.x + dot(uPsiD[3 * v + c], br.yzw);
        scale[c] += uPsiW[v] * rho * varrho;
      }
    }
  }
  outColor = vec4(scale * a + offset, 1.0);
}`;

  const surfaceFS = (shading) => surfaceTemplate.replace("LIGHT_FUNCTIONS", lightFunctions(shading));

  // The depth pre-pass: every pixel is then shaded once, by its nearest surface.
  const depthFS = header + `
out vec4 outColor;
void main() { outColor = vec4(0.0); }`;

  const quadVS = header + `
void main() {
  vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}`;

  // Sum of (luminance, surface pixels) over the 4x4 block of the source under each output texel.
  const reduceFS = header + LUMA + `
uniform sampler2D uSrc;
uniform ivec2 uSrcSize;
uniform int uFirst;
out vec4 outColor;
void main() {
  ivec2 base = ivec2(gl_FragCoord.xy) * 4;
  vec2 acc = vec2(0.0);
  for (int j = 0; j < 4; j++) {
    for (int i = 0; i < 4; i++) {
      ivec2 p = base + ivec2(i, j);
      if (p.x >= uSrcSize.x || p.y >= uSrcSize.y) continue;
      vec4 v = texelFetch(uSrc, p, 0);
      acc += uFirst == 1 ? vec2(dot(LUMA, v.rgb) * v.a, v.a) : v.xy;
    }
  }
  outColor = vec4(acc, 0.0, 1.0);
}`;

  const compositeFS = header + LUMA + `
uniform sampler2D uSurface;
uniform sampler2D uSums;
uniform int uHasKappa;
uniform vec3 uKappa;
uniform float uGain;           // the user's exposure (x the reference gain)
uniform int uAuto;
uniform vec4 uAE;              // a, b, brightness range
out vec4 outColor;
float srgb(float c) {
  c = clamp(c, 0.0, 1.0);
  return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}
void main() {
  vec4 v = texelFetch(uSurface, ivec2(gl_FragCoord.xy), 0);
  vec2 s = texelFetch(uSums, ivec2(0), 0).xy;
  float l0 = s.y > 0.0 ? s.x / s.y : 0.0;
  vec3 extra = vec3(0.0);
  if (uHasKappa == 1) {
    float kl = dot(LUMA, uKappa);
    extra = uKappa * (max(l0, 0.0) / max(1.0 - kl, 0.05));
  }
  float g = uGain;
  if (uAuto == 1) {
    float l = l0 + dot(LUMA, extra);
    l = l > 0.0 ? clamp(l, uAE.z, uAE.w) : uAE.z;
    g *= exp(uAE.x + uAE.y * log(l));
  }
  vec3 lin = v.a > 0.5 ? (v.rgb + extra) * g : vec3(0.0);
  outColor = vec4(srgb(lin.r), srgb(lin.g), srgb(lin.b), 1.0);
}`;

  return { surfaceVS, surfaceFS, depthFS, quadVS, reduceFS, compositeFS };
})();
