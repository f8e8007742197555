// The features strip drawn by the page: each Gaussian of a TF alone, in its own colours, over a
// faint grey ghost of the whole (the server's CacheViews.render_feature, ghost 0.1).

const GHOST = 0.1;

/**
 * Pictures of each Gaussian of `tf` alone, from `camera`, as PNG data URLs:
 * [{index, image}], in TF order. `renderer` is a GLVolumeRenderer with its volume set.
 */
export function featurePictures(renderer, { tf, camera, size, shading, background }) {
  const n = size * size;
  const full = renderer.renderRGBA({ tf, camera, width: size, height: size, shading });
  const bg = background.map((c) => c * 255);
  // The ghost layer: the whole picture's luminance, GHOST of the way from the background.
  const layer = new Float32Array(n * 3);
  for (let p = 0; p < n; p++) {
    const t = 1 - full[p * 4 + 3] / 255;
    const r = full[p * 4] + t * bg[0];
    const g = full[p * 4 + 1] + t * bg[1];
    const b = full[p * 4 + 2] + t * bg[2];
    const grey = 0.299 * r + 0.587 * g + 0.114 * b;
    for (let c = 0; c < 3; c++) layer[p * 3 + c] = (1 - GHOST) * bg[c] + GHOST * grey;
  }
  const canvas = document.createElement("canvas");
  canvas.width = size;
  canvas.height = size;
  const ctx = canvas.getContext("2d");
  const out = [];
  tf.gaussians.forEach((g, index) => {
    const one = { ...tf, gaussians: [g] };
    const px = renderer.renderRGBA({ tf: one, camera, width: size, height: size, shading });
    const img = ctx.createImageData(size, size);
    for (let p = 0; p < n; p++) {
      const t = 1 - px[p * 4 + 3] / 255;
      for (let c = 0; c < 3; c++) img.data[p * 4 + c] = Math.min(255, Math.round(px[p * 4 + c] + t * layer[p * 3 + c]));
      img.data[p * 4 + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    out.push({ index, image: canvas.toDataURL("image/png") });
  });
  return out;
}
