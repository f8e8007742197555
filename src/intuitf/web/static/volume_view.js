// Volume interaction view: the current result, rendered by the page itself with WebGL2
// (gl_view.js: full resolution while dragging, hand edits and toggles at once, pick and outline
// from an attribution pass on the GPU), or, where the page cannot, by the server frame by frame
// over the WebSocket /api/view.
//
// Server frames:
// Drag rotates (azimuth, elevation); shift-drag or right-drag pans; the wheel zooms. While
// dragging the server sends small JPEG frames, on release one full PNG; only the newest
// request is ever rendered (one frame in flight, the latest camera waiting). A click without a
// drag picks the feature under the cursor (the smallest projected area among those that make
// the pixel): its outline is drawn at once and it is selected in the decomposition view.

import * as api from "./api.js";
import { pickBar } from "./gl_renderer.js";
import * as glv from "./gl_view.js";
import { showError, showMessage } from "./messages.js";
import {
  DEFAULT_CAMERA,
  cameraJSON,
  defaultTF,
  hexToRgb,
  on,
  runVolumeId,
  set,
  splitQid,
  state,
} from "./state.js";

const ACCENT = [255, 197, 66]; // the selection colour (amber)
const MAX_SIZE = 512;

let stage;
let canvas;
let ctx;
let maskCanvas;
let statsEl;
let pickInfo;
let titleEl;
let socket;
let viewSize = 256;
let drag = null;
let wheelTimer = null;
let lastTargetKey = "";
let frameCount = 0;
let noteEl;
let glPending = null; // the quality of the page frame waiting for the next animation frame

export function initVolumeView() {
  stage = document.getElementById("view-stage");
  canvas = document.getElementById("view-canvas");
  ctx = canvas.getContext("2d");
  maskCanvas = document.getElementById("mask-canvas");
  statsEl = document.getElementById("view-stats");
  pickInfo = document.getElementById("pick-info");
  titleEl = document.getElementById("view-title");
  noteEl = document.createElement("div");
  noteEl.id = "view-note";
  noteEl.className = "view-note";
  noteEl.setAttribute("aria-live", "polite");
  stage.append(noteEl);
  glv.initGLView({
    // In software, a volume's first picture comes at half resolution, the full one right after.
    onReady: () => frame(glv.progressive() ? "first" : "full"),
    onNote: (text) => {
      noteEl.textContent = text;
    },
  });

  socket = new api.ViewSocket({
    onFrame: showFrame,
    onError: (e) => {
      setBusy(false);
      showMessage(e.error || "The view could not be rendered.", { kind: "error", hint: e.hint || "" });
    },
    onStatus: (s) => stage.classList.toggle("offline", s !== "open"),
  });

  // Controls beside the view.
  const shade = document.getElementById("shade-toggle");
  shade.checked = state.shaded;
  shade.addEventListener("change", () => set({ shaded: shade.checked }));
  const bg = document.getElementById("bg-color");
  bg.value = state.background;
  bg.addEventListener("input", () => set({ background: bg.value }));
  document.getElementById("reset-camera").addEventListener("click", () => resetCamera());

  // Pointer interaction.
  canvas.addEventListener("pointerdown", onDown);
  canvas.addEventListener("pointermove", onMove);
  canvas.addEventListener("pointerup", onUp);
  // A double-click selects the whole of what is under the cursor: every feature that makes
  // the pixel (a pot drawn by a dense core and a rim), not only the smallest.
  canvas.addEventListener("dblclick", (e) => {
    if (!state.sketching) pickAt(e, e.ctrlKey || e.metaKey || e.altKey, true);
  });
  canvas.addEventListener("pointercancel", () => {
    drag = null;
  });
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", onWheel, { passive: false });

  new ResizeObserver(() => resize()).observe(stage);
  resize();

  on(["run", "current", "candidate", "draft", "shaded", "background", "selected", "volumeId", "volumes", "histogram"], () =>
    frame(state.draftDragging ? "drag" : "full"),
  );
  on("camera", () => frame("full"));
  // A chosen volume starts loading into the page at once, beside its histogram.
  on("volumeId", () => {
    if (!state.run && state.volumeId) glv.ensureVolume(state.volumeId, variantOf(state.volumeId));
    if (!state.run && state.volumeId) previewCamera(state.volumeId);
  });
  on(["pick", "selected", "camera"], drawOverlay);
  // The last click's note goes with it (another result, run or volume; a cleared selection).
  on(["pick", "selected"], () => {
    const p = state.pick;
    if (!p || (p.index !== null && p.index !== undefined && !state.selected.size)) pickInfo.textContent = "";
  });
  on(["current", "draft", "run", "volumeId", "histogram"], updateTitle);
  on("runDetail", () => {
    // A run's judging camera is where its pictures (and a sketch's base) come from.
    const cam = state.runDetail && state.runDetail.camera;
    if (cam && !state.cameraTouched && !sameCamera(normCamera(cam), state.camera)) set({ camera: normCamera(cam) });
  });
  updateTitle();
  window.intuitfDebug = { state, get frames() { return frameCount; }, socket, gl: glv };
}

function normCamera(c) {
  const out = {
    azimuth: c.azimuth || 0,
    elevation: c.elevation || 0,
    zoom: c.zoom || 1,
    pan: Array.isArray(c.pan) ? [c.pan[0] || 0, c.pan[1] || 0] : [0, 0],
  };
  if (c.roll) out.roll = c.roll;
  if (c.fov) out.fov = c.fov;
  if (c.projection) out.projection = c.projection;
  return out;
}

function sameCamera(a, b) {
  return JSON.stringify(cameraJSON(a)) === JSON.stringify(cameraJSON(b));
}

/** The view a volume is previewed from before any run: the one its runs would judge from. */
let volumeView = { volume: null, camera: null };

async function previewCamera(id) {
  if (volumeView.volume !== id) {
    volumeView = { volume: id, camera: null };
    try {
      const got = await api.get(`/api/volumes/${api.enc(id)}/camera`);
      if (volumeView.volume === id) volumeView.camera = normCamera(got.camera);
    } catch {
      return; // the default view then: the preview still shows the volume
    }
  }
  const cam = volumeView.camera;
  if (cam && !state.run && state.volumeId === id && !state.cameraTouched && !sameCamera(cam, state.camera)) {
    set({ camera: cam });
  }
}

/** The judging camera of the current run (where the sketch is drawn), else the view the
 * volume on preview is shown from, else the default. */
export function judgingCamera() {
  const cam = state.runDetail && state.runDetail.camera;
  if (cam) return normCamera(cam);
  if (!state.run && volumeView.camera && volumeView.volume === state.volumeId) return { ...volumeView.camera };
  return { ...DEFAULT_CAMERA, pan: [0, 0] };
}

export function resetCamera() {
  state.cameraTouched = false;
  set({ camera: judgingCamera() });
}

export function renderSize() {
  return viewSize;
}

function resize() {
  const r = stage.getBoundingClientRect();
  const side = Math.max(64, Math.floor(Math.min(r.width, r.height)));
  // The server renders at most MAX_SIZE; the picture is scaled to fill the view.
  const size = Math.max(128, Math.min(MAX_SIZE, Math.round((side * Math.min(window.devicePixelRatio || 1, 1.5)) / 32) * 32));
  for (const c of [canvas, maskCanvas, document.getElementById("sketch-canvas")]) {
    c.style.setProperty("width", `${side}px`);
    c.style.setProperty("height", `${side}px`);
  }
  if (size !== viewSize || canvas.width !== size) {
    viewSize = size;
    canvas.width = size;
    canvas.height = size;
    set({ viewSize: size });
    frame("full");
  }
}

function target() {
  if (state.draft) {
    const vol = runVolumeId();
    // A hand edit of a run's result is drawn on the run's volume (its own voxel size).
    return vol ? { volume: vol, tf: state.draft, ...(state.run ? { run: state.run } : {}) } : null;
  }
  if (state.current) return { candidate: state.current };
  // No run yet: the chosen volume with a TF on its histogram's materials, to look at first.
  if (!state.run && state.volumeId && state.histogram && state.histogram.volume === state.volumeId) {
    return { volume: state.volumeId, tf: defaultTF(state.histogram.materials) };
  }
  return null;
}

/** Ask for a frame of the current target from the current camera ("drag" or "full"). */
export function frame(quality = "full") {
  if (!socket) return;
  const t = target();
  if (!t) {
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    stage.classList.add("empty");
    stage.querySelector(".view-empty").textContent = state.run
      ? `${state.run}: the first results appear here when its first generation ends.`
      : "Choose a volume or start a run to see a rendering here.";
    return;
  }
  stage.classList.remove("empty");
  const gt = pageTarget(t);
  if (gt) {
    const st = glv.ensureVolume(gt.volume, variantOf(gt.volume));
    if (st === "ready") {
      pageFrame(quality);
      return;
    }
    if (st === "loading") {
      setBusy(true); // the first picture comes when the volume is in the page
      return;
    }
  }
  const msg = {
    target: t,
    camera: cameraJSON(),
    size: viewSize,
    shaded: state.shaded,
    background: hexToRgb(state.background),
    quality: quality === "drag" ? "drag" : "full",
  };
  if (state.selected.size) msg.highlight = [...state.selected].sort((a, b) => a - b);
  lastTargetKey = JSON.stringify(t).slice(0, 200);
  setBusy(true);
  socket.request(msg);
}

/** What the page's copy of volume `id` depends on besides the file: its voxel size. */
function variantOf(id) {
  const v = state.volumes.find((x) => x.id === id);
  return v && v.spacing ? v.spacing.join(",") : "";
}

/** Whether the page holds volume `id` as the server now gives it, ready to draw. */
function pageReady(id) {
  return glv.ready(id, variantOf(id));
}

/** {volume, tf} when the page renders `t` itself (its volume known to the server by id), else null. */
function pageTarget(t) {
  if (!glv.renderer() || !t) return null;
  const c = state.candidate;
  const d = state.runDetail;
  let gt = null;
  if (t.volume) gt = { volume: t.volume, tf: t.tf };
  else if (t.candidate && c && c.qid === t.candidate && c.tf && d && d.volume_id) gt = { volume: d.volume_id, tf: c.tf };
  // A run's result, or a hand edit of it, made before its volume got another voxel size is
  // drawn by the server, as judged.
  if (gt && (t.run || t.candidate) && !glv.sameVoxels(gt.volume, d && d.spacing)) return null;
  return gt;
}

/** Why the server draws a run's view the page could draw: the run's voxels differ ("" if not). */
function voxelNote() {
  const d = state.runDetail;
  const t = target();
  if (!glv.renderer() || !d || !d.volume_id || !t || !(t.candidate || t.run)) return "";
  if (glv.sameVoxels(d.volume_id, d.spacing)) return "";
  const size = d.spacing.map((v) => Number(v.toPrecision(4))).join(" × ");
  return `${d.info.name} was made with voxels of ${size}, not the volume's voxel size now: the server draws its view, as it was judged.`;
}

/** Draw a page frame at the next animation frame (many requests in one frame draw once). */
function pageFrame(quality) {
  const first = glPending === null;
  if (glPending !== "full") glPending = quality;
  if (first) requestAnimationFrame(drawPageFrame);
}

let bandTicket = 0;

function drawPageFrame() {
  const quality = glPending || "full";
  glPending = null;
  const gt = pageTarget(target());
  if (!gt || !pageReady(gt.volume)) return frame(quality);
  const camera = cameraJSON();
  const my = ++bandTicket; // a newer frame stops an older one drawn in bands
  const opts = { tf: gt.tf, camera, size: viewSize, shading: state.shaded, background: hexToRgb(state.background), quality };
  if (glv.banded(quality, viewSize)) {
    glv.drawBanded(ctx, opts, () => my !== bandTicket).then((res) => {
      if (res && my === bandTicket) pageFrameDone(res, quality, gt, camera);
    });
    return;
  }
  pageFrameDone(glv.draw(ctx, opts), quality, gt, camera);
}

function pageFrameDone(res, quality, gt, camera) {
  setBusy(false);
  frameCount += 1;
  canvas.dataset.quality = quality;
  canvas.dataset.frames = String(frameCount);
  canvas.dataset.renderer = "webgl2";
  const sw = glv.renderer().software ? " (software)" : "";
  statsEl.textContent = `${res.width}² ${quality} · ${Math.round(res.ms)} ms · WebGL2${sw}`;
  const base = glv.note();
  noteEl.textContent = res.reduced
    ? `${base ? `${base} ` : ""}Dragging at ${res.width}² (software WebGL is slow here); ${viewSize}² on release.`
    : base;
  if (quality === "first") setTimeout(() => frame("full"), 0);
  if (quality === "full") {
    set({ viewSettled: { camera, size: viewSize, shaded: state.shaded, key: JSON.stringify(t0key(gt)), n: frameCount } });
    if (state.selected.size) drawOverlay();
    // Once the view rests, the attribution pass for a click (a pick then costs no pass).
    clearTimeout(prepareTimer);
    prepareTimer = setTimeout(() => {
      const now = pageTarget(target());
      const pickable = (splitQid(state.current) || (!state.run && now && target().volume)) && !state.draft;
      if (glPending === null && !drag && now && pickable && pageReady(now.volume)) glv.prepare(now.tf, cameraJSON(), viewSize);
    }, 200);
  }
}

let prepareTimer = null;

function t0key(gt) {
  return [gt.volume, gt.tf && gt.tf.gaussians].map((x) => JSON.stringify(x)).join("|").slice(0, 200);
}

/** The features strip drawn by the page from the settled camera, or null (then the server). */
export function pageFeatures(size) {
  const gt = pageTarget(target());
  if (!gt || state.draft) return null;
  const cam = (state.viewSettled && state.viewSettled.camera) || cameraJSON();
  return glv.features(gt.volume, { tf: gt.tf, camera: cam, size, shading: state.shaded, background: hexToRgb(state.background) });
}

function setBusy(b) {
  stage.classList.toggle("busy", b);
}

async function showFrame(header, blob) {
  if (!socket.busy) setBusy(false);
  // A frame asked of the server before the page could draw this view (its volume or the
  // result's TF still on the way) is stale once the page draws it: it would cover the page's.
  const gt = pageTarget(target());
  if (gt && pageReady(gt.volume)) return;
  let bitmap;
  try {
    bitmap = await createImageBitmap(blob);
  } catch (err) {
    return; // a frame that does not decode is skipped; the next one replaces it
  }
  ctx.imageSmoothingEnabled = true;
  ctx.imageSmoothingQuality = "high";
  ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
  bitmap.close && bitmap.close();
  frameCount += 1;
  canvas.dataset.quality = header.quality || "";
  canvas.dataset.frames = String(frameCount);
  canvas.dataset.req = String(header.req || "");
  const ms = header.ms !== undefined ? Math.round(header.ms) : "?";
  const render = header.render_ms !== undefined ? ` (render ${Math.round(header.render_ms)})` : "";
  statsEl.textContent = `${header.width || "?"}×${header.height || "?"} ${header.quality || ""} · ${ms} ms${render}`;
  canvas.dataset.renderer = "server";
  if (glv.renderer()) noteEl.textContent = voxelNote() || glv.note();
  if (header.quality === "full" && !socket.busy) {
    set({ viewSettled: { camera: cameraJSON(), size: viewSize, shaded: state.shaded, key: lastTargetKey, n: frameCount } });
  }
}

function updateTitle() {
  const cur = splitQid(state.current);
  titleEl.textContent = state.draft
    ? `Editing ${state.current || "a new TF"} by hand`
    : cur
      ? `${cur.run} / ${cur.cid}`
      : state.run
        ? `${state.run} (no result yet)`
        : state.volumeId
        ? `${state.volumeId} · preview on its histogram's materials`
        : "nothing to show yet";
}

// -- pointer interaction ------------------------------------------------------------------------
function onDown(e) {
  if (state.sketching) return;
  if (e.button !== 0 && e.button !== 2) return;
  canvas.setPointerCapture(e.pointerId);
  drag = {
    x: e.clientX,
    y: e.clientY,
    cam: { ...state.camera, pan: [...state.camera.pan] },
    pan: e.button === 2 || e.shiftKey,
    moved: false,
    mods: { add: e.ctrlKey || e.metaKey || e.altKey },
  };
}

function onMove(e) {
  if (!drag) return;
  const dx = e.clientX - drag.x;
  const dy = e.clientY - drag.y;
  if (!drag.moved && Math.hypot(dx, dy) < 4) return;
  drag.moved = true;
  stage.classList.add("dragging");
  const r = canvas.getBoundingClientRect();
  const c = drag.cam;
  if (drag.pan) {
    state.camera = { ...c, pan: [c.pan[0] + dx / r.width, c.pan[1] - dy / r.height] };
  } else {
    // The drag as seen in the camera before its roll: sideways turns about the picture's
    // vertical, up and down tilts, whatever way the judging camera turned the picture.
    const roll = ((c.roll || 0) * Math.PI) / 180;
    const sx = dx * Math.cos(roll) + dy * Math.sin(roll);
    const sy = dy * Math.cos(roll) - dx * Math.sin(roll);
    state.camera = {
      ...c,
      azimuth: (((c.azimuth - (sx * 180) / r.width) % 360) + 360) % 360,
      elevation: Math.max(-89, Math.min(89, c.elevation + (sy * 180) / r.height)),
    };
  }
  state.cameraTouched = true;
  drawOverlay();
  frame("drag");
}

function onUp(e) {
  if (!drag) return;
  const d = drag;
  drag = null;
  stage.classList.remove("dragging");
  if (d.moved) {
    set({ camera: state.camera }); // the full frame, the features and the overlay follow
    return;
  }
  if (e.button === 0 || e.button === 2) pickAt(e, d.mods.add);
}

function onWheel(e) {
  if (state.sketching) return;
  e.preventDefault();
  const c = state.camera;
  const zoom = Math.max(0.25, Math.min(8, c.zoom * Math.exp(-e.deltaY * 0.0015)));
  state.camera = { ...c, zoom };
  state.cameraTouched = true;
  drawOverlay();
  frame("drag");
  clearTimeout(wheelTimer);
  wheelTimer = setTimeout(() => set({ camera: state.camera }), 220);
}

// -- picking ---------------------------------------------------------------------------------------
let pickSeq = 0; // a server pick answers only if no later click came first
// A single click's pick by the server waits this long for a second click: a double-click's
// two clicks would otherwise send two picks ahead of its whole one, and the server computes
// each (three where one is asked). The page's own pick is instant and never waits.
const DOUBLE_CLICK_MS = 300;
let singlePick = null;

async function pickAt(e, add, whole = false) {
  const seq = ++pickSeq;
  const r = canvas.getBoundingClientRect();
  const x = Math.min(viewSize - 1, Math.max(0, Math.floor(((e.clientX - r.left) / r.width) * viewSize)));
  const y = Math.min(viewSize - 1, Math.max(0, Math.floor(((e.clientY - r.top) / r.height) * viewSize)));
  const cur = splitQid(state.current);
  const t = target();
  const preview = !cur && t && t.volume && !state.draft ? t : null; // a volume before any run
  if ((!cur && !preview) || state.draft) {
    if (state.draft) showMessage("Keep or discard the hand edit before selecting features.", { kind: "info" });
    return;
  }
  const camera = cameraJSON();
  const was = state.current;
  const gt = pageTarget(t);
  if (gt && pageReady(gt.volume) && glv.canPick()) {
    // The page's own pick: an attribution pass on the GPU and the smallest-area rule.
    clickStart = performance.now();
    const res = glv.pick(gt.tf, camera, viewSize, x, y, whole);
    applyPick(res, { camera, x, y, add, whole });
    return;
  }
  clearTimeout(singlePick);
  singlePick = null;
  if (!whole) {
    singlePick = setTimeout(() => {
      singlePick = null;
      serverPick(seq, preview, cur, was, { camera, x, y, add, whole });
    }, DOUBLE_CLICK_MS);
    return;
  }
  await serverPick(seq, preview, cur, was, { camera, x, y, add, whole });
}

async function serverPick(seq, preview, cur, was, { camera, x, y, add, whole }) {
  try {
    const path = preview
      ? `/api/volumes/${api.enc(preview.volume)}/pick`
      : `/api/candidates/${api.enc(cur.run)}/${api.enc(cur.cid)}/pick`;
    const res = await api.post(path, {
      ...(preview ? { tf: preview.tf } : {}),
      camera,
      x,
      y,
      size: viewSize,
      shaded: state.shaded,
      background: hexToRgb(state.background), // the still's background: one sample cache for both
      whole,
    });
    if (state.current !== was || seq !== pickSeq) return;
    applyPick(res, { camera, x, y, add, whole });
  } catch (err) {
    showError(err);
  }
}

let clickStart = null;

function applyPick(res, { camera, x, y, add, whole }) {
  {
    state.follow = false;
    let selected;
    if (res.index === null || res.index === undefined) {
      selected = add ? new Set(state.selected) : new Set();
      pickInfo.textContent = "Nothing visible here: selection cleared.";
    } else if (whole) {
      // Everything under the cursor joins (a Ctrl-double-click adds it to the selection).
      const picked = res.selected && res.selected.length ? res.selected : [res.index];
      selected = new Set(add ? state.selected : []);
      for (const i of picked) selected.add(i);
      const names = picked.map((i) => i + 1).join(", ");
      pickInfo.textContent =
        picked.length > 1
          ? `Selected features ${names}: all ${picked.length} that make this pixel.`
          : `Selected feature ${names}: the only one that makes this pixel.`;
    } else {
      selected = new Set(add ? state.selected : []);
      if (add && state.selected.has(res.index)) selected.delete(res.index);
      else selected.add(res.index);
      // The pick's candidates: the features that make the pixel (a speck that only tints it
      // is visible there but was not in the running).
      const vis = res.visible || [];
      const bar = pickBar(vis);
      const n = vis.filter((v) => v[1] >= bar).length;
      pickInfo.textContent = `Selected feature ${res.index + 1}${
        n > 1 ? ` (the smallest of the ${n} that make this pixel; double-click for all ${n})` : ""
      }.`;
    }
    set({ pick: { ...res, camera, size: viewSize, x, y }, selected });
  }
}

// -- the selection overlay ---------------------------------------------------------------------------
let maskCache = { uri: null, data: null };

async function maskPixels(uri, size) {
  if (maskCache.uri === uri && maskCache.data && maskCache.data.width === size) return maskCache.data;
  const img = new Image();
  img.src = uri;
  await img.decode();
  const off = document.createElement("canvas");
  off.width = size;
  off.height = size;
  const octx = off.getContext("2d");
  octx.drawImage(img, 0, 0, size, size);
  const data = octx.getImageData(0, 0, size, size);
  maskCache = { uri, data };
  return data;
}

/** The selection's pixels from the page's attribution pass: {bits, index} or null. */
function pageSelection() {
  const gt = pageTarget(target());
  if (!gt || !pageReady(gt.volume) || !glv.canPick() || state.draft || !state.selected.size) return null;
  const indices = [...state.selected].sort((a, b) => a - b);
  const bits = glv.selectionMask(gt.tf, cameraJSON(), viewSize, indices);
  return bits ? { bits, index: indices.join(",") } : null;
}

async function drawOverlay() {
  const p = state.pick;
  const mctx = maskCanvas.getContext("2d");
  const pt = pageTarget(target());
  if (pt && glv.canPick() && pageReady(pt.volume)) {
    // Drawn by the page: the selected features' outline, for the camera on view (none while
    // the camera moves; the frame after it stops brings it back).
    const sel = drag && drag.moved ? null : pageSelection();
    if (!sel) {
      mctx.clearRect(0, 0, maskCanvas.width, maskCanvas.height);
      maskCanvas.dataset.index = "";
      return;
    }
    paintMask(mctx, viewSize, (i) => sel.bits[i] === 1, sel.index);
    if (clickStart !== null) {
      glv.stats.clickToOutlineMs = Math.round(performance.now() - clickStart);
      clickStart = null;
    }
    return;
  }
  const show = p && p.mask && p.index !== null && state.selected.has(p.index) && sameCamera(p.camera, state.camera) && !state.draft;
  if (!show) {
    mctx.clearRect(0, 0, maskCanvas.width, maskCanvas.height);
    maskCanvas.dataset.index = "";
    return;
  }
  const size = p.size;
  let src;
  try {
    src = await maskPixels(p.mask, size);
  } catch (_) {
    return;
  }
  if (state.pick !== p) return;
  const a = src.data;
  paintMask(mctx, size, (i) => a[i * 4 + 3] > 96, String(p.index));
}

/** Paint a selection (inside(i) per pixel) on the mask layer: outline opaque, inside faint. */
function paintMask(mctx, size, inside, index) {
  maskCanvas.width = size;
  maskCanvas.height = size;
  const out = mctx.createImageData(size, size);
  let count = 0;
  for (let y = 0; y < size; y++) {
    for (let x = 0; x < size; x++) {
      const i = y * size + x;
      if (!inside(i)) continue;
      count += 1;
      const edge =
        x === 0 || y === 0 || x === size - 1 || y === size - 1 || !inside(i - 1) || !inside(i + 1) || !inside(i - size) || !inside(i + size);
      const o = i * 4;
      out.data[o] = ACCENT[0];
      out.data[o + 1] = ACCENT[1];
      out.data[o + 2] = ACCENT[2];
      out.data[o + 3] = edge ? 255 : 70;
    }
  }
  mctx.putImageData(out, 0, 0);
  maskCanvas.dataset.index = index;
  maskCanvas.dataset.pixels = String(count);
}

