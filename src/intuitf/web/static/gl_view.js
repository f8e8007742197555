// The volume view rendered by the page itself (WebGL2): which volume is loaded, the frames, the
// pick and the selection's outline, and the notes that say when the page falls back.
//
// volume_view.js asks here first; where this module cannot render (no WebGL2, a volume the
// page cannot hold, a run whose volume the server does not list) it says why and the view
// uses the server's frames, as before.

import { featurePictures } from "./gl_features.js";
import { GLVolumeRenderer, featureMask, pickSmallest } from "./gl_renderer.js";
import { blockRanges, fetchVolume } from "./gl_volume.js";
import { tfKey } from "./gl_tf.js";

/** Software rendering only: a drag frame slower than this lowers the drag resolution. */
export const DRAG_BUDGET_MS = 100;
const DRAG_SCALES = [1, 0.75, 0.5, 0.375, 0.25];

let R = null;
let problem = null;
let vol = { id: null, variant: "", status: "none", note: "", started: 0 };
let ticket = 0;
let callbacks = { onReady: () => {}, onNote: () => {} };
let dragLevel = 0;
let attrCache = { key: "", attr: null };

/** What the page has measured (read by the benchmark and the tests). */
export const stats = {
  frames: 0,
  last: null, // {quality, ms, width, height}
  firstPicture: {}, // volume id → ms from choosing it to its first picture
  firstFull: {}, // volume id → ms from choosing it to its first full-resolution picture
  loadMs: {}, // volume id → ms to fetch and upload its texture
  pickMs: null,
};

/** Set up the renderer; `onReady(id)` when a volume is loaded, `onNote(text)` for the note. */
export function initGLView({ onReady, onNote }) {
  callbacks = { onReady: onReady || (() => {}), onNote: onNote || (() => {}) };
  try {
    R = new GLVolumeRenderer();
  } catch (err) {
    R = null;
    problem = `${err && err.message ? err.message : err}: the server renders the view.`;
    callbacks.onNote(problem);
  }
  if (R) R.canvas.addEventListener("webglcontextlost", lost);
}

function lost(e) {
  e.preventDefault();
  problem = "The page's WebGL2 context was lost: the server renders the view.";
  R = null;
  vol = { id: null, variant: "", status: "none", note: "", started: 0 };
  callbacks.onNote(problem);
}

export function renderer() {
  return R;
}

/**
 * "ready", "loading", "failed" or "none" for volume `id`; starts loading a new one. `variant`
 * names what else the texture depends on (the voxel size set for a raw file): a new one loads
 * the volume again, with the size the server now gives it.
 */
export function ensureVolume(id, variant = "") {
  if (!R || !id) return "none";
  if (vol.id === id && vol.variant === variant) return vol.status;
  const my = ++ticket;
  vol = { id, variant, status: "loading", note: "", started: performance.now() };
  callbacks.onNote(`Loading ${id} into the page…`);
  load(id, my);
  return "loading";
}

async function load(id, my) {
  try {
    const data = await fetchVolume(id, R.limits(), {
      onProgress: (f) => {
        if (my === ticket) callbacks.onNote(`Loading ${id} into the page… ${Math.round(f * 100)}%`);
      },
    });
    if (my !== ticket) return;
    const blocks = await blockRanges(data);
    if (my !== ticket) return;
    await R.setVolume(data, blocks);
    if (my !== ticket) return;
    stats.loadMs[id] = Math.round(performance.now() - vol.started);
    attrCache = { key: "", attr: null };
    msPerPx = null;
    vol.status = "ready";
    vol.note =
      data.step > 1
        ? `Downsampled ${data.step}× per axis to ${data.dims.join("×")} (from ${data.fullDims.join("×")}) to fit this browser; the judge's pictures use the full volume.`
        : "";
    callbacks.onNote(vol.note);
    callbacks.onReady(id);
  } catch (err) {
    if (my !== ticket) return;
    vol.status = "failed";
    vol.note = `The page cannot render ${id} (${err && err.message ? err.message : err}): the server renders the view.`;
    callbacks.onNote(vol.note);
  }
}

/** The note the view shows now (empty when there is nothing to say). */
export function note() {
  return problem || vol.note || "";
}

/**
 * Whether the page's copy of volume `id` has the proportions of voxels of size `spacing`
 * ([x, y, z]): a run keeps the voxel size it was made with, the volume may since have been
 * given another. True while there is nothing to compare (no spacing, the copy not loaded).
 */
export function sameVoxels(id, spacing) {
  if (!R || !spacing || vol.id !== id || vol.status !== "ready") return true;
  const m = Math.min(...spacing);
  return R.invSpacing.every((v, i) => Math.abs(v - m / spacing[i]) <= 1e-6);
}

export function ready(id, variant = "") {
  return !!R && vol.id === id && vol.variant === variant && vol.status === "ready";
}

/**
 * Draw `tf` into the 2-D context `ctx` (its canvas is size × size): at full resolution, or while
 * dragging in software at a lower one when the last drag frame was over budget.
 * Returns {ms, width, height, reduced}.
 */
export function draw(ctx, { tf, camera, size, shading, background, quality }) {
  let scale = 1;
  if (quality === "drag" && R.software) scale = DRAG_SCALES[dragLevel];
  if (quality === "first") scale = R.software ? 0.5 : 1;
  const side = Math.max(16, Math.round(size * scale));
  const ms = R.render({ tf, camera, width: side, height: side, shading, background });
  ctx.imageSmoothingEnabled = true;
  ctx.imageSmoothingQuality = "high";
  ctx.drawImage(R.canvas, 0, 0, ctx.canvas.width, ctx.canvas.height);
  if (quality === "drag" && R.software) {
    // Adapt for the next drag frame: what a full-size frame would cost, against the budget.
    const perPx = ms / (side * side);
    let level = 0;
    while (level < DRAG_SCALES.length - 1 && perPx * (size * DRAG_SCALES[level]) ** 2 > DRAG_BUDGET_MS) level++;
    dragLevel = level;
  }
  return finish(quality, ms, side, size);
}

/** Software only: a full frame expected to take longer than this is drawn in bands, the
 * page answering between them (a newer frame stops an older one's bands). */
export const BAND_MS = 120;
let msPerPx = null;

/** Whether a frame of `quality` at size² should be drawn in bands (software, slow frames). */
export function banded(quality, size) {
  // Unknown cost (a volume's first frame): in bands, to be safe.
  return !!R && R.software && quality === "full" && (msPerPx === null || msPerPx * size * size > 1.5 * BAND_MS);
}

/**
 * Draw a full frame in horizontal bands, yielding to the page between them; each band shows
 * as soon as it is drawn. `stale()` → true stops it (resolves null). Resolves like draw().
 */
export async function drawBanded(ctx, { tf, camera, size, shading, background }, stale) {
  const n = msPerPx === null ? 32 : Math.min(32, Math.ceil((msPerPx * size * size) / BAND_MS));
  const step = Math.ceil(size / n);
  let ms = 0;
  if (R.canvas.width !== size || R.canvas.height !== size) {
    R.canvas.width = size;
    R.canvas.height = size;
  }
  const sx = ctx.canvas.width / size;
  for (let y0 = 0; y0 < size; y0 += step) {
    const y1 = Math.min(size, y0 + step);
    ms += R.render({ tf, camera, width: size, height: size, shading, background, rows: [y0, y1] });
    // GL rows count from the bottom; the canvas's from the top.
    ctx.drawImage(R.canvas, 0, size - y1, size, y1 - y0, 0, (size - y1) * sx, ctx.canvas.width, (y1 - y0) * sx);
    await new Promise((r) => setTimeout(r, 0));
    if (stale()) return null;
  }
  return finish("full", ms, size, size);
}

function finish(quality, ms, side, size) {
  msPerPx = msPerPx === null ? ms / (side * side) : 0.5 * msPerPx + (0.5 * ms) / (side * side);
  stats.frames += 1;
  stats.last = { quality, ms: Math.round(ms * 10) / 10, width: side, height: side };
  if (vol.id && stats.firstPicture[vol.id] === undefined) {
    stats.firstPicture[vol.id] = Math.round(performance.now() - vol.started);
  }
  if (quality === "full" && vol.id && stats.firstFull[vol.id] === undefined) {
    stats.firstFull[vol.id] = Math.round(performance.now() - vol.started);
  }
  return { ms, width: side, height: side, reduced: side < size };
}

function attrKey(tf, camera, size) {
  return JSON.stringify([vol.id, tfKey(tf), camera, size]);
}

let prepTicket = 0;

function attribution(tf, camera, size) {
  const key = attrKey(tf, camera, size);
  if (attrCache.key !== key) {
    prepTicket += 1; // a pass in bands for another view is no longer wanted
    stats.attributionPasses = (stats.attributionPasses || 0) + 1;
    stats.lastAttributionKey = key;
    const attr = R.attribution({ tf, camera, width: size, height: size });
    attrCache = { key, attr };
  }
  return attrCache.attr;
}

/**
 * Compute the attribution for a view ahead of a click (after the view settles), so a click
 * finds it ready: the outline then follows within the frame.
 */
export async function prepare(tf, camera, size) {
  if (!canPick()) return;
  const key = attrKey(tf, camera, size);
  if (attrCache.key === key) return;
  const my = ++prepTicket;
  const t0 = performance.now();
  let attr;
  if (R.software) {
    // In bands, the page answering between them (a click meanwhile makes its own pass).
    const bands = msPerPx === null ? 32 : Math.min(32, Math.max(1, Math.ceil((msPerPx * size * size) / BAND_MS)));
    attr = await R.attributionBanded({ tf, camera, width: size, height: size }, bands, () => my !== prepTicket);
    if (!attr || my !== prepTicket) return;
  } else attr = R.attribution({ tf, camera, width: size, height: size });
  stats.attributionPasses = (stats.attributionPasses || 0) + 1;
  stats.lastAttributionKey = key;
  attrCache = { key, attr };
  stats.prepared = { ms: Math.round(performance.now() - t0), size };
}

/** Whether a volume's first picture comes at half resolution first (software only). */
export function progressive() {
  return !!R && R.software;
}

/** The pick can run here (float render targets): otherwise the server picks. */
export function canPick() {
  return !!R && R.floatTargets;
}

/** The paper's pick at pixel (x, y) (`whole`: every feature that makes it):
 * {index, visible: [[i, share, area]], selected, mask (Uint8Array)}. */
export function pick(tf, camera, size, x, y, whole = false) {
  const t0 = performance.now();
  const attr = attribution(tf, camera, size);
  const res = pickSmallest(attr, Math.min(16, tf.gaussians.length), size, size, x, y, whole);
  stats.pickMs = Math.round(performance.now() - t0);
  return res;
}

/** Pixels (Uint8Array size × size) where any of the Gaussians `indices` is visible. */
export function selectionMask(tf, camera, size, indices) {
  const valid = indices.filter((i) => i >= 0 && i < Math.min(16, tf.gaussians.length));
  if (!valid.length) return null;
  return featureMask(attribution(tf, camera, size), valid, size, size);
}

/** The features strip's pictures, drawn here: [{index, image}] (null when the page cannot). */
export function features(volumeId, { tf, camera, size, shading, background }) {
  if (!ready(volumeId)) return null;
  return featurePictures(R, { tf, camera, size, shading, background });
}
