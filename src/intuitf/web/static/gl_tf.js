// The transfer function's lookup table, computed in the page exactly as the server computes it
// (intuitf.tf.gaussian.GaussianTF.lut and VolumeRenderer.lut), so the page classifies every
// sample as the judge's pictures do.
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
    const s = size > 1 ? k / (size - 1) : 0;
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
    let a = Math.min(1, Math.max(0, total));
    if (sampleDistance !== 1) a = 1 - Math.pow(1 - a, sampleDistance);
    // Rounded to float32 first, as the server's table is float32 when it is thresholded.
    const a32 = Math.fround(a);
    out[k * 4] = clamp01(r);
    out[k * 4 + 1] = clamp01(g);
    out[k * 4 + 2] = clamp01(b);
    out[k * 4 + 3] = a32 < ALPHA_EPSILON ? 0 : a32;
  }
  return out;
}

function clamp01(x) {
  return x < 0 ? 0 : x > 1 ? 1 : x;
}

/** occupied[k] = number of entries below k with non-zero alpha (length L + 1). */
export function occupancy(lut) {
  const n = lut.length / 4;
  const occ = new Int32Array(n + 1);
  for (let k = 0; k < n; k++) occ[k + 1] = occ[k] + (lut[k * 4 + 3] > 0 ? 1 : 0);
  return occ;
}

/** A stable key of what the LUT depends on (to skip rebuilding an unchanged one). */
export function tfKey(tf) {
  return JSON.stringify(gaussiansOf(tf).map((g) => [g.mean, g.width, g.height, g.color]));
}
