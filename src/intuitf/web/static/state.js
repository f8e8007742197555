// The page's shared state: one plain object, changed only through set(), with listeners per key.
//
// Views never talk to each other directly: they read `state`, call set() and listen with on().

export const DEFAULT_CAMERA = Object.freeze({ azimuth: 0, elevation: 0, zoom: 1, pan: [0, 0] });

export const state = {
  info: null, // GET /api/info
  volumes: [], // GET /api/volumes
  volumeId: null, // the volume a new run starts on (and the histogram's, with no run)
  tree: [], // GET /api/tree
  tab: null, // the root run whose history tab is open
  run: null, // the current run's name
  runDetail: null, // GET /api/runs/{run}
  current: null, // the current candidate, "RUN/gGGG-NNN"
  candidate: null, // GET /api/candidates/{run}/{cid} of `current` (its TF included)
  follow: true, // the current candidate follows the run's newest best
  selected: new Set(), // Gaussians of the current TF that a refinement changes
  pick: null, // the last click's {index, mask, camera, size}: drawn over the view
  camera: { ...DEFAULT_CAMERA },
  shaded: true,
  background: "#000000",
  draft: null, // a TF being edited by hand (null when not editing)
  editIndex: 0, // the Gaussian the hand editor's colour picker changes
  sketching: false, // strokes go to the sketch layer instead of the camera
  marked: [], // gallery candidates marked for compare / better-than / best / worst
  histogram: null, // GET /api/volumes/{id}/histogram of the volume on view
};

const listeners = new Map();

/** Change state keys and tell their listeners (each listener once per call). */
export function set(patch) {
  const called = new Set();
  Object.assign(state, patch);
  for (const key of Object.keys(patch)) {
    for (const fn of listeners.get(key) || []) {
      if (called.has(fn)) continue;
      called.add(fn);
      try {
        fn(state, key);
      } catch (err) {
        console.error(err);
        reportError(err);
      }
    }
  }
}

/** Call fn(state, key) whenever one of `keys` (a name or a list) is set. */
export function on(keys, fn) {
  for (const key of [].concat(keys)) {
    if (!listeners.has(key)) listeners.set(key, []);
    listeners.get(key).push(fn);
  }
}

let errorSink = (err) => console.error(err);
export function setErrorSink(fn) {
  errorSink = fn;
}
export function reportError(err) {
  errorSink(err);
}

/** "RUN/gGGG-NNN" → {run, cid}; null for anything else. */
export function splitQid(qid) {
  const m = /^([^/]+)\/(g\d{3,}-\d{3,})$/.exec(qid || "");
  return m ? { run: m[1], cid: m[2] } : null;
}

/** The generation number of a candidate id "gGGG-NNN" (or of a qid). */
export function generationOf(id) {
  const m = /g(\d{3,})-\d{3,}$/.exec(id || "");
  return m ? parseInt(m[1], 10) : null;
}

/** The camera as the API wants it (only the fields Camera.from_dict knows). */
export function cameraJSON(cam = state.camera) {
  const out = {
    azimuth: round(cam.azimuth, 2),
    elevation: round(cam.elevation, 2),
    zoom: round(cam.zoom, 4),
    pan: [round(cam.pan[0], 4), round(cam.pan[1], 4)],
  };
  // A judging camera chosen to show the object upright turns the picture (roll); the view and
  // every picture asked of the server keep it, or the bonsai lies on its side.
  if (cam.roll) out.roll = round(cam.roll, 2);
  if (cam.fov && cam.fov !== 30) out.fov = round(cam.fov, 2);
  if (cam.projection === "orthographic") out.projection = "orthographic";
  return out;
}

/** "#rrggbb" → [r, g, b] in 0..1. */
export function hexToRgb(hex) {
  const m = /^#?([0-9a-f]{2})([0-9a-f]{2})([0-9a-f]{2})$/i.exec(hex || "");
  if (!m) return [0, 0, 0];
  return [1, 2, 3].map((i) => round(parseInt(m[i], 16) / 255, 4));
}

/** [r, g, b] in 0..1 → "#rrggbb". */
export function rgbToHex(rgb) {
  return (
    "#" +
    rgb
      .map((c) =>
        Math.round(Math.max(0, Math.min(1, c)) * 255)
          .toString(16)
          .padStart(2, "0"),
      )
      .join("")
  );
}

export function round(x, digits) {
  const k = 10 ** digits;
  return Math.round(x * k) / k;
}

/** The TF the views show: the hand-edit draft while editing, else the current candidate's. */
export function shownTF() {
  if (state.draft) return state.draft;
  if (state.candidate) return state.candidate.tf;
  if (!state.run && !state.current && state.histogram && state.histogram.volume === state.volumeId) {
    return defaultTF(state.histogram.materials); // the preview of a volume before any run
  }
  return null;
}

/** The volume id of the current run (falls back to the chosen volume). */
export function runVolumeId() {
  const d = state.runDetail;
  if (d && d.volume_id) return d.volume_id;
  if (d && d.info && d.info.volume) {
    const v = state.volumes.find((x) => x.id === d.info.volume || x.name === d.info.volume);
    if (v) return v.id;
  }
  return state.volumeId;
}

/** A small element helper: el("div.cls#id", {attrs}, children...). */
export function el(spec, attrs = {}, ...children) {
  const m = /^([a-z0-9]+)?((?:[.#][\w-]+)*)$/i.exec(spec);
  const node = document.createElement((m && m[1]) || "div");
  for (const part of ((m && m[2]) || "").match(/[.#][\w-]+/g) || []) {
    if (part[0] === ".") node.classList.add(part.slice(1));
    else node.id = part.slice(1);
  }
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "text") node.textContent = v;
    else if (k === "on") for (const [ev, fn] of Object.entries(v)) node.addEventListener(ev, fn);
    else if (k === "dataset") Object.assign(node.dataset, v);
    else if (k === "style") for (const [p, val] of Object.entries(v)) node.style.setProperty(p, val);
    else if (v === true) node.setAttribute(k, "");
    else node.setAttribute(k, v);
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return node;
}

export function fmtRating(r) {
  return r === null || r === undefined || Number.isNaN(r) ? "–" : Math.round(r).toString();
}

export function fmtUsd(x) {
  if (!x) return "$0";
  return x < 0.01 ? `$${x.toFixed(4)}` : `$${x.toFixed(2)}`;
}

export function fmtSeconds(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  if (s < 60) return `${Math.round(s)} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`;
  return `${Math.floor(s / 3600)} h ${Math.round((s % 3600) / 60)} min`;
}

const PALETTE = [
  [0.85, 0.45, 0.35],
  [0.95, 0.85, 0.6],
  [0.45, 0.65, 0.9],
  [0.6, 0.85, 0.5],
  [0.8, 0.55, 0.85],
  [0.95, 0.65, 0.3],
];

/** A TF to look at a volume before any run: one Gaussian per histogram material. */
export function defaultTF(materials) {
  let mats = (materials || []).filter((m) => m && m.mean > 0.02).slice(0, 6);
  if (!mats.length) mats = [{ mean: 0.3, width: 0.05 }, { mean: 0.6, width: 0.05 }, { mean: 0.85, width: 0.05 }];
  const n = mats.length;
  return {
    format: "intuitf.gaussian-tf",
    version: 1,
    name: "preview",
    gaussians: mats.map((m, i) => ({
      mean: Math.min(1, Math.max(0, m.mean)),
      width: Math.min(0.5, Math.max(0.01, m.width || 0.04)),
      height: n === 1 ? 0.6 : 0.1 + (0.7 * i) / (n - 1),
      color: PALETTE[i % PALETTE.length],
      frozen: false,
    })),
  };
}
