import { TABLE_SIZE } from "./gl_tf.js";

// GLSL ES 3.0 sources of the page's ray marcher: the server's kernels (render/kernels.py
// `march` and `attribute`) written for the fragment shader, one ray per pixel.
//
// Same rays (ViewFrame packed), same box (voxel centres [0, n-1]), samples at t0 + k·dt from
// box entry, trilinear value (the texture's linear filter), pre-integrated classification of
// the segment from the previous sample (the table gl_tf.preintegratedTable builds as the
// server does, interpolated by the texture's filter; the LUT with linear interpolation between
// entries where the two values lie within one table entry), front-to-back premultiplied
// compositing, early ray
// termination at T < 1/255, empty-space skipping that keeps the sample grid (over blocks of 2–16
// cells, a jump across a whole cube of empty ones where the grid allows: gl_volume.visibleBlocks),
// and Blinn–Phong with a two-sided headlight from the gradient: the server's precomputed
// central differences as an 8-bit texture, trilinearly filtered, once the page has built it
// (until then the central difference of the trilinear field at ±1 voxel, which equals it inside
// the box, at six fetches a sample instead of one).

/**
 * The ray loop of both shaders, inside main() once the ray (oi, di) and its box span t are
 * known: it calls the shader's `bool visit(int k, vec3 p, bool visible)` for each sample that
 * can show (p its position; true ends the ray). With pre-integration a sample is classified by
 * the segment from the one before it (kernels._classify), so skipping keeps every segment that
 * can show, as kernels.march does: the first sample of a skipped stretch is still visited when
 * the one before it lay in a visible block (`carry`: the segment out of a structure), and
 * `visit` reads the value before a sample whose predecessor was skipped (`have` false: the
 * segment into it).
 */
const MARCH = `  if (t.y >= t.x) {
    int n = int((t.y - t.x) / u_dt) + 1;
    int k = 0;
    bool done = false;
    while (k < n && !done) {
      // Block by block: a skipped block costs one lookup, a visible one runs its samples
      // with no bookkeeping per sample (a sample just past its exit lies in a neighbour's
      // cells, whose value range then holds it: an invisible neighbour gives it alpha 0).
      ivec3 b = blockOf(oi + (t.x + float(k) * u_dt) * di);
      // gl_volume.visibleBlocks: 128 + q, every block within q of this one is empty and the
      // ray leaves that cube at once; q < 128, the blocks within q are visible and the ray
      // runs the samples of that cube with no lookup in between.
      int v = int(texelFetch(u_vis, b, 0).r * 255.0 + 0.5);
      int kn = skipCube(b, v & 127, oi, di, t.x, k);
      if (v >= 128) {
        if (carry) {
          done = visit(k, oi + (t.x + float(k) * u_dt) * di, false);
          carry = false;
          have = kn == k + 1;
        } else {
          have = false;
        }
        k = kn;
        continue;
      }
      for (int kend = min(kn, n); k < kend; k++) {
        if (visit(k, oi + (t.x + float(k) * u_dt) * di, true)) {
          done = true;
          break;
        }
      }
    }
  }
`;

export const VERTEX = `#version 300 es
void main() {
  // One triangle that covers the viewport.
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}`;

const COMMON = `
precision highp float;
precision highp int;
precision highp sampler3D;
precision highp sampler2D;

uniform sampler3D u_vol;   // R8 (original bytes) or R16F (normalised values), linear filter
uniform sampler3D u_vis;   // R8 per block (gl_volume.visibleBlocks's byte / 255), nearest
uniform sampler2D u_lut;   // RGBA32F (L × 1), straight colour, linear filter
uniform sampler2D u_table; // TABLE × TABLE pre-integrated, premultiplied (row: front value)
uniform vec3 u_dims;       // nx, ny, nz
uniform vec3 u_invDims;    // 1 / (nx, ny, nz)
uniform ivec3 u_nb;        // blocks per axis
uniform vec3 u_is;         // 1 / spacing (spacing in units of the smallest)
uniform vec2 u_map;        // normalised = texel * u_map.x + u_map.y
uniform int u_nl;          // LUT entries
uniform float u_dt;        // sample distance (world units)
uniform float u_tstop;     // early ray termination
uniform vec3 u_eye;
uniform vec3 u_fwd;
uniform vec3 u_right;
uniform vec3 u_up;
uniform vec4 u_view;       // half width, half height, pan x, pan y
uniform vec2 u_size;       // picture width, height
uniform int u_persp;


// textureLod, not texture: no implicit derivatives to work out (software rasterisers do).
float value(vec3 p) {
  // No clamp to the box: the texture's CLAMP_TO_EDGE gives a point outside it the value at the
  // edge, as the server's clamped index does.
  return textureLod(u_vol, (p + 0.5) * u_invDims, 0.0).r * u_map.x + u_map.y;
}

vec4 lutAt(int q) {
  return texelFetch(u_lut, ivec2(q, 0), 0);
}

// Entry x (a fractional index) interpolated between its neighbours by the texture's filter.
vec4 lutLerp(float x) {
  return textureLod(u_lut, vec2((x + 0.5) / float(u_nl), 0.5), 0.0);
}

vec2 slab(float o, float d, float hi, vec2 t) {
  if (abs(d) < 1e-12) {
    if (o < 0.0 || o > hi) return vec2(1.0, 0.0);
    return t;
  }
  float ta = (0.0 - o) / d;
  float tb = (hi - o) / d;
  if (ta > tb) { float s = ta; ta = tb; tb = s; }
  return vec2(max(t.x, ta), min(t.y, tb));
}

// The ray of this pixel: origin and unit direction (world), as kernels._ray.
void pixelRay(out vec3 o, out vec3 d) {
  float x = (gl_FragCoord.x / u_size.x * 2.0 - 1.0 - 2.0 * u_view.z) * u_view.x;
  float y = (gl_FragCoord.y / u_size.y * 2.0 - 1.0 - 2.0 * u_view.w) * u_view.y;
  if (u_persp == 1) {
    o = u_eye;
    d = normalize(u_fwd + x * u_right + y * u_up);
  } else {
    o = u_eye + x * u_right + y * u_up;
    d = u_fwd;
  }
}

// The first sample index at or after the exit of the cube of blocks within r of block b (r = 0:
// the block itself, as kernels.march skips one).
int skipCube(ivec3 b, int r, vec3 oi, vec3 di, float t0, int k) {
  float tex = 1e30;
  vec3 lo = vec3(b - r) * float(BSIZE);
  vec3 hi = vec3(b + r + 1) * float(BSIZE);
  if (di.x > 1e-12) tex = min(tex, (hi.x - oi.x) / di.x);
  else if (di.x < -1e-12) tex = min(tex, (lo.x - oi.x) / di.x);
  if (di.y > 1e-12) tex = min(tex, (hi.y - oi.y) / di.y);
  else if (di.y < -1e-12) tex = min(tex, (lo.y - oi.y) / di.y);
  if (di.z > 1e-12) tex = min(tex, (hi.z - oi.z) / di.z);
  else if (di.z < -1e-12) tex = min(tex, (lo.z - oi.z) / di.z);
  int kn = int(ceil((tex - t0) / u_dt - 1e-4));
  return kn > k ? kn : k + 1;
}

ivec3 blockOf(vec3 p) {
  ivec3 i = ivec3(max(p, vec3(0.0)));
  return min(i / BSIZE, u_nb - 1);
}

// The ray's state between samples (MARCH): its index-space direction, and with
// pre-integration the value of the sample before (vf, when have) and whether that sample lay
// in a visible block (carry).
vec3 g_di;
float vf = 0.0;
bool have = false;
bool carry = false;

// This pixel's ray in index space (oi, di; d its world direction) and its span in the box.
vec2 indexRay(out vec3 oi, out vec3 di, out vec3 d) {
  vec3 o;
  pixelRay(o, d);
  oi = o * u_is;
  di = d * u_is;
  g_di = di;
  vec2 t = slab(oi.x, di.x, u_dims.x - 1.0, vec2(0.0, 1e30));
  t = slab(oi.y, di.y, u_dims.y - 1.0, t);
  return slab(oi.z, di.z, u_dims.z - 1.0, t);
}

// Pre-integrated classification of the segment from value vfront to vback
// (kernels._classify): the table's bilinear entry (premultiplied, by the texture's filter)
// where the two lie a table entry apart or more, else the LUT at vback. Straight colour.
vec4 classify(float vfront, float vback) {
  float pf = vfront * float(TABLE - 1);
  float pb = vback * float(TABLE - 1);
  if (PREINT == 1 && abs(pb - pf) >= 1.0) {
    vec4 e = textureLod(u_table, vec2((pb + 0.5) / float(TABLE), (pf + 0.5) / float(TABLE)), 0.0);
    return e.a > 0.0 ? vec4(e.rgb / e.a, e.a) : vec4(0.0);
  }
  return lutLerp(vback * float(u_nl - 1));
}
`;

/**
 * GLSL for x^n (x in [0, 1]) by repeated squaring when the specular exponent `n` is a whole
 * number up to 64 (the page's 24: five multiplications), else exp2(n·log2 x) with the
 * uniform. In software a multiplication costs a fraction of exp2 and log2 (measured on the
 * bonsai at 512²: shaded frames 10–20 % faster), and the picture is the same.
 */
function specularPower(n) {
  if (!Number.isInteger(n) || n < 1 || n > 64) {
    return "float specPow(float x) { return exp2(u_shade.w * log2(max(x, 1e-30))); }";
  }
  const lines = ["float specPow(float x) {", "  float p1 = x;"];
  const used = [];
  for (let k = 0; 1 << k <= n; k++) {
    if (k > 0) lines.push(`  float p${1 << k} = p${1 << (k - 1)} * p${1 << (k - 1)};`);
    if (n & (1 << k)) used.push(`p${1 << k}`);
  }
  lines.push(`  return ${used.join(" * ")};`, "}");
  return lines.join("\n");
}

/**
 * The ray marcher's source for one kind of picture: `shading` (Blinn–Phong or emission only)
 * and `gradient` (normals from the 8-bit gradient texture, or central differences of the
 * volume texture). Each kind is its own program: a software rasteriser runs a branch on a
 * uniform inside the loop at a real cost, a constant one not at all. `packed`: the gradient
 * texture also holds the 8-bit value (alpha), so a shaded sample is one fetch in all.
 * `shininess`: the specular exponent, built in (see specularPower). `blockSize`: the edge (cells)
 * of the empty-space-skipping grid (gl_volume.blockSize), built in.
 */
export function renderSource({ shading, gradient, packed = false, shininess = null, blockSize = 8, preintegrated = true }) {
  return `#version 300 es
#define BSIZE ${blockSize}
#define SHADING ${shading ? 1 : 0}
#define GRADIENT_TEXTURE ${gradient ? 1 : 0}
#define PACKED_VALUE ${packed ? 1 : 0}
#define PREINT ${preintegrated ? 1 : 0}
#define TABLE ${TABLE_SIZE}
${COMMON}
uniform vec4 u_shade;      // ambient, diffuse, specular, shininess
uniform sampler3D u_grad;  // RGBA8 gradient codes (128 = 0; alpha: the r8 value), linear filter
uniform vec2 u_gcode;      // gradient = (texel - u_gcode.x) * u_gcode.y, normalised units per voxel
uniform vec3 u_bg;
uniform int u_alphaOut;    // 1: premultiplied RGBA (for compositing in the page), 0: over u_bg
out vec4 outColor;

${specularPower(shininess)}

vec3 g_l;
vec3 g_h;
vec3 acc = vec3(0.0);
float tr = 1.0;

// The value a sample reads: the packed gradient texture's byte, else the volume texture.
float sampleValue(vec3 p) {
#if PACKED_VALUE
  return textureLod(u_grad, (p + 0.5) * u_invDims, 0.0).a * u_map.x + u_map.y;
#else
  return value(p);
#endif
}

bool visit(int k, vec3 p, bool visible) {
#if PACKED_VALUE
  vec4 vg = textureLod(u_grad, (p + 0.5) * u_invDims, 0.0);
  float v = vg.a * u_map.x + u_map.y;
#else
  float v = value(p);
#endif
#if PREINT
  if (!have) vf = k > 0 ? sampleValue(p - u_dt * g_di) : v;
  vec4 e = classify(vf, v);
  vf = v;
  have = true;
  carry = visible;
#else
  vec4 e = lutLerp(v * float(u_nl - 1));
#endif
  float a = e.a;
  if (a > 0.0) {
    vec3 c = e.rgb;
#if SHADING
#if PACKED_VALUE
    vec3 g = (vg.rgb - u_gcode.x) * u_gcode.y * u_is;
#elif GRADIENT_TEXTURE
    vec3 g = (textureLod(u_grad, (p + 0.5) * u_invDims, 0.0).rgb - u_gcode.x) * u_gcode.y * u_is;
#else
    vec3 g = 0.5 * vec3(
      value(p + vec3(1.0, 0.0, 0.0)) - value(p - vec3(1.0, 0.0, 0.0)),
      value(p + vec3(0.0, 1.0, 0.0)) - value(p - vec3(0.0, 1.0, 0.0)),
      value(p + vec3(0.0, 0.0, 1.0)) - value(p - vec3(0.0, 0.0, 1.0))) * u_is;
#endif
    // |g| >= 1e-3 as the server's kernel, without branches (cheaper in software).
    float m2 = dot(g, g);
    float inv = inversesqrt(max(m2, 1e-12));
    bool lit = m2 >= 1e-6;
    float ndl = lit ? abs(dot(g, g_l)) * inv : 1.0;
    float sp = lit ? specPow(min(abs(dot(g, g_h)) * inv, 1.0)) : 0.0;
    c = min(vec3(1.0), c * (u_shade.x + u_shade.y * ndl) + u_shade.z * sp);
#endif
    acc += tr * a * c;
    tr *= 1.0 - a;
    if (tr < u_tstop) return true;
  }
  return false;
}

void main() {
  vec3 oi, di, d;
  vec2 t = indexRay(oi, di, d);
  g_l = -u_fwd;
  vec3 h = g_l - d;
  float hn = length(h);
  g_h = hn < 1e-12 ? g_l : h / hn;
${MARCH}  outColor = u_alphaOut == 1 ? vec4(acc, 1.0 - tr) : vec4(acc + tr * u_bg, 1.0);
}`;
}

/**
 * Per-feature attribution (kernels.attribute over the sample cache's nearest-entry samples):
 * each Gaussian's part of the pixel's accumulated opacity, four Gaussians per RGBA target.
 * `groups` (1–4) is how many targets: the source is made for it, with the Gaussians in vec4s
 * (no arrays indexed at run time, which software rasterisers keep in memory). `blockSize` as
 * renderSource's.
 */
export function attributeSource(groups, blockSize = 8, preintegrated = true) {
  const g = [0, 1, 2, 3].slice(0, groups);
  return `#version 300 es
#define BSIZE ${blockSize}
#define PREINT ${preintegrated ? 1 : 0}
#define TABLE ${TABLE_SIZE}
${COMMON}
uniform vec4 u_mean[4];
uniform vec4 u_width[4];   // unused slots: width 1, height 0
uniform vec4 u_height[4];
${g.map((i) => `layout(location = ${i}) out vec4 out${i};`).join("\n")}
${g.map((i) => `vec4 part${i} = vec4(0.0);`).join("\n")}
float tr = 1.0;
int qf = 0; // the previous sample's LUT entry (with pre-integration)

// erf (Abramowitz and Stegun 7.1.26, within 1.5e-7), per component.
vec4 erf4(vec4 x) {
  vec4 s = sign(x);
  vec4 a = abs(x);
  vec4 t = 1.0 / (1.0 + 0.3275911 * a);
  vec4 y = 1.0 - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592) * t * exp(-a * a);
  return s * y;
}

bool visit(int k, vec3 p, bool visible) {
  float scale = float(u_nl - 1);
  int q = clamp(int(value(p) * scale + 0.5), 0, u_nl - 1);
  float a = lutAt(q).a;
  int ti = 0;
  int tj = 0;
#if PREINT
  if (!have) qf = k > 0 ? clamp(int(value(p - u_dt * g_di) * scale + 0.5), 0, u_nl - 1) : q;
  if (qf != q) {
    // kernels.pair_entry: the LUT entries on the table's grid.
    float r = float(TABLE - 1) / scale;
    ti = u_nl == TABLE ? qf : int(float(qf) * r + 0.5);
    tj = u_nl == TABLE ? q : int(float(q) * r + 0.5);
    if (ti != tj) a = texelFetch(u_table, ivec2(tj, ti), 0).a;
  }
  qf = q;
  have = true;
  carry = visible;
#endif
  if (a > 0.0) {
    float total = 0.0;
${g.map((i) => `    vec4 c${i};`).join("\n")}
    if (ti != tj) {
      // Each Gaussian's opacity density over the segment's values (kernels._mass).
      float lo = float(min(ti, tj)) / float(TABLE - 1);
      float hi = float(max(ti, tj)) / float(TABLE - 1);
${g.map((i) => `      vec4 k${i} = 1.0 / (u_width[${i}] * 1.4142135623730951);
      c${i} = u_height[${i}] * u_width[${i}] * (erf4((hi - u_mean[${i}]) * k${i}) - erf4((lo - u_mean[${i}]) * k${i}));`).join("\n")}
      total = ${g.map((i) => `dot(c${i}, vec4(1.0))`).join(" + ")};
    }
    if (total <= 0.0) {
      float s = float(q) / scale;
${g.map((i) => `      vec4 z${i} = (vec4(s) - u_mean[${i}]) / u_width[${i}];
      c${i} = u_height[${i}] * exp(-0.5 * z${i} * z${i});`).join("\n")}
      total = ${g.map((i) => `dot(c${i}, vec4(1.0))`).join(" + ")};
    }
    if (total > 0.0) {
      float w = tr * a / total;
${g.map((i) => `      part${i} += w * c${i};`).join("\n")}
    }
    tr *= 1.0 - a;
    if (tr < u_tstop) return true;
  }
  return false;
}

void main() {
  vec3 oi, di, d;
  vec2 t = indexRay(oi, di, d);
${MARCH}${g.map((i) => `  out${i} = part${i};`).join("\n")}
}`;
}
