// The transfer function's lookup table and pre-integrated table, computed in the page exactly
// as the server computes them (intuitf.tf.gaussian.GaussianTF.lut, VolumeRenderer.lut and
// intuitf.tf.preintegration), so the page classifies every sample as the judge's pictures do.
//
// Entry k is the value s = k / (L - 1). Opacity density: the Gaussians' sum clamped to [0, 1],
// corrected for the sample distance, 1 - (1 - a) ** step; entries below ALPHA_EPSILON are empty
// (Gaussian tails must not defeat empty-space skipping). Colour: the Gaussians' colours
// weighted by their contribution at s; where every contribution underflows, the colour of the
// Gaussian nearest in standardised distance.

/** LUT alphas below this are treated as empty (render/renderer.py ALPHA_EPSILON). */
export const ALPHA_EPSILON = 1e-5;

/** The TF's Gaussians as plain arrays (a TF JSON as the API sends it). */
export function gaussiansOf(tf) {
  return (tf && tf.gaussians) || [];
}

/**
 * (L × 4) straight RGBA as a Float32Array: the server's table for `tf`, `size` entries and
 * a step of `sampleDistance` voxels.
 */
export function tfLut(tf, size, sampleDistance) {
  const gs = gaussiansOf(tf);
  const out = new Float32Array(size * 4);
  const comps = new Float64Array(gs.length);
  for (let k = 0; k < size; k++) {
    const [total, r, g, b] = classifyAt(gs, size > 1 ? k / (size - 1) : 0, comps);
    let a = total;
    if (sampleDistance !== 1) a = 1 - Math.pow(1 - a, sampleDistance);
    // Rounded to float32 first, as the server's table is float32 when it is thresholded.
    const a32 = Math.fround(a);
    out[k * 4] = r;
    out[k * 4 + 1] = g;
    out[k * 4 + 2] = b;
    out[k * 4 + 3] = a32 < ALPHA_EPSILON ? 0 : a32;
  }
  return out;
}

function clamp01(x) {
  return x < 0 ? 0 : x > 1 ? 1 : x;
}

/**
 * occupied[k] = number of entries below k where a sample can show (length L + 1): entries
 * with non-zero alpha, and with pre-integration those within one table entry of one
 * (renderer.Classification.occupied).
 */
export function occupancy(lut, preintegrated = true) {
  const n = lut.length / 4;
  const reach = preintegrated ? Math.ceil((n - 1) / (TABLE_SIZE - 1)) : 0;
  const shows = new Uint8Array(n);
  for (let k = 0; k < n; k++) {
    if (lut[k * 4 + 3] > 0) shows.fill(1, Math.max(0, k - reach), Math.min(n, k + reach + 1));
  }
  const occ = new Int32Array(n + 1);
  for (let k = 0; k < n; k++) occ[k + 1] = occ[k] + shows[k];
  return occ;
}

// -- pre-integration (intuitf.tf.preintegration) ------------------------------------------------

/** Entries per axis of the pre-integrated table (preintegration.TABLE_SIZE). */
export const TABLE_SIZE = 256;
const SUBSTEPS = 8;
const MAX_OPACITY = 1 - 1e-6;

/** Opacity density (clamped to [0, 1]) and colour of `gs` at value s (GaussianTF.opacity,
 * .color); `comps` is scratch space, one entry per Gaussian. */
function classifyAt(gs, s, comps) {
  let total = 0;
  for (let i = 0; i < gs.length; i++) {
    const z = (s - gs[i].mean) / gs[i].width;
    comps[i] = gs[i].height * Math.exp(-0.5 * z * z);
    total += comps[i];
  }
  let r = 0;
  let g = 0;
  let b = 0;
  if (total > 1e-12) {
    for (let i = 0; i < gs.length; i++) {
      const c = gs[i].color;
      r += comps[i] * c[0];
      g += comps[i] * c[1];
      b += comps[i] * c[2];
    }
    r /= total;
    g /= total;
    b /= total;
  } else if (gs.length) {
    let best = 0;
    let bestD = Infinity;
    for (let i = 0; i < gs.length; i++) {
      const d = Math.abs(s - gs[i].mean) / gs[i].width;
      if (d < bestD) {
        bestD = d;
        best = i;
      }
    }
    [r, g, b] = gs[best].color;
  }
  return [Math.min(1, Math.max(0, total)), clamp01(r), clamp01(g), clamp01(b)];
}

/**
 * The server's pre-integrated table (preintegrated_table, premultiplied): TABLE_SIZE ×
 * TABLE_SIZE × 4 Float32Array, row f (front sample's value) and column b (back sample's),
 * for a step of `sampleDistance` voxels.
 */
export function preintegratedTable(tf, sampleDistance) {
  const gs = gaussiansOf(tf);
  const n = TABLE_SIZE;
  const fine = (n - 1) * SUBSTEPS + 1;
  const ds = 1 / (fine - 1);
  const comps = new Float64Array(gs.length);
  // Cumulative integrals of the extinction τ and of colour · τ (trapezoids), at the entries.
  const T = new Float64Array(n);
  const K = new Float64Array(n * 3);
  let t = 0;
  let kr = 0;
  let kg = 0;
  let kb = 0;
  let prev = null;
  for (let m = 0; m < fine; m++) {
    const [a, r, g, b] = classifyAt(gs, m / (fine - 1), comps);
    const tau = -Math.log1p(-Math.min(a, MAX_OPACITY));
    const cur = [tau, r * tau, g * tau, b * tau];
    if (prev) {
      t += 0.5 * (cur[0] + prev[0]) * ds;
      kr += 0.5 * (cur[1] + prev[1]) * ds;
      kg += 0.5 * (cur[2] + prev[2]) * ds;
      kb += 0.5 * (cur[3] + prev[3]) * ds;
    }
    prev = cur;
    if (m % SUBSTEPS === 0) {
      const e = m / SUBSTEPS;
      T[e] = t;
      K[e * 3] = kr;
      K[e * 3 + 1] = kg;
      K[e * 3 + 2] = kb;
    }
  }
  const out = new Float32Array(n * n * 4);
  const d = sampleDistance;
  for (let f = 0; f < n; f++) {
    for (let b = f; b < n; b++) {
      let a;
      let r;
      let g;
      let bl;
      if (f === b) {
        const [op, cr, cg, cb] = classifyAt(gs, f / (n - 1), comps);
        a = -Math.expm1(d * Math.log1p(-Math.min(op, MAX_OPACITY)));
        r = cr;
        g = cg;
        bl = cb;
      } else {
        const dt = T[b] - T[f];
        a = -Math.expm1(-d * Math.max((dt * (n - 1)) / (b - f), 0));
        if (Math.abs(dt) > 1e-12) {
          r = (K[b * 3] - K[f * 3]) / dt;
          g = (K[b * 3 + 1] - K[f * 3 + 1]) / dt;
          bl = (K[b * 3 + 2] - K[f * 3 + 2]) / dt;
        } else {
          r = g = bl = 0;
        }
      }
      if (a < ALPHA_EPSILON) a = 0;
      r = clamp01(r) * a;
      g = clamp01(g) * a;
      bl = clamp01(bl) * a;
      for (const [i, j] of [[f, b], [b, f]]) {
        const o = (i * n + j) * 4;
        out[o] = r;
        out[o + 1] = g;
        out[o + 2] = bl;
        out[o + 3] = a;
      }
    }
  }
  return out;
}

/** A stable key of what the LUT depends on (to skip rebuilding an unchanged one). */
export function tfKey(tf) {
  return JSON.stringify(gaussiansOf(tf).map((g) => [g.mean, g.width, g.height, g.color]));
}
