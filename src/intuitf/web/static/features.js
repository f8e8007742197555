// Feature decomposition: each Gaussian of the current TF rendered alone, from the volume view's
// camera. Clicking one selects (or deselects) it; the volume view highlights the selection, and
// a query with features selected refines only those.

import * as api from "./api.js";
import { showError } from "./messages.js";
import { el, hexToRgb, on, rgbToHex, runVolumeId, set, shownTF, splitQid, state } from "./state.js";
import { pageFeatures } from "./volume_view.js";

const TILE = 128;

let strip;
let note;
let clearBtn;
let pending = null;
let ticket = 0;
let shownKey = "";

export function initFeatures() {
  strip = document.getElementById("features-strip");
  note = document.getElementById("features-note");
  clearBtn = document.getElementById("features-clear");
  clearBtn.addEventListener("click", () => set({ selected: new Set() }));
  on(["candidate", "viewSettled", "shaded", "background", "histogram", "run", "volumeId"], schedule);
  on(["selected"], markSelection);
  on(["run", "runDetail", "volumeId"], loadStructures);
  render([]);
}

function schedule() {
  clearTimeout(pending);
  pending = setTimeout(load, 250);
}

/** The TF whose features are shown, and where to ask for them: the current candidate, or
 * the preview of a volume with no run (its TF on the histogram's materials). */
function source() {
  const cand = state.candidate;
  const cur = splitQid(state.current);
  if (cand && cur) return { tf: cand.tf, path: `/api/candidates/${api.enc(cur.run)}/${api.enc(cur.cid)}/features`, key: state.current };
  const tf = !state.run && !state.current && !state.draft ? shownTF() : null;
  if (tf && state.volumeId) return { tf, path: `/api/volumes/${api.enc(state.volumeId)}/features`, key: `volume:${state.volumeId}`, body: { tf } };
  return null;
}

async function load() {
  const src = source();
  if (!src) {
    shownKey = "";
    render([]);
    return;
  }
  const camera = (state.viewSettled && state.viewSettled.camera) || null;
  const body = {
    camera: camera || { azimuth: 0, elevation: 0, zoom: 1, pan: [0, 0] },
    size: TILE,
    shaded: state.shaded,
    background: hexToRgb(state.background),
  };
  Object.assign(body, src.body || {});
  const key = JSON.stringify([src.key, body]);
  if (key === shownKey) return;
  const my = ++ticket;
  // Where the page renders the view itself (WebGL2), it draws the strip too.
  const local = pageFeatures(TILE);
  if (local) {
    shownKey = key;
    render(local);
    return;
  }
  strip.classList.add("loading");
  try {
    const feats = await api.post(src.path, body);
    if (my !== ticket) return;
    shownKey = key;
    render(feats);
  } catch (err) {
    if (my === ticket) showError(err);
  } finally {
    if (my === ticket) strip.classList.remove("loading");
  }
}

// -- what each feature is: the volume's structure its values fall on, and its near-twins -------
let structures = { volume: null, list: [] };

async function loadStructures() {
  const id = state.run ? runVolumeId() : state.volumeId;
  if (!id || structures.volume === id) return;
  structures = { volume: id, list: [] };
  try {
    const list = await api.get(`/api/volumes/${api.enc(id)}/structures`);
    if (structures.volume !== id) return;
    structures = { volume: id, list };
    shownKey = "";
    schedule();
  } catch (_) {
    /* the labels are a help: without them each feature keeps its number and value */
  }
}

/** What a structure is called: its name where a model gave one, else what it looks like and
 * where it is ("blob, bottom"). */
export function structureName(s) {
  return s.name || `${s.shape}, ${s.position}`;
}

/** The structures whose values a Gaussian at `mean` falls on, the best fit first: the one whose
 * value range has `mean` nearest its middle (relative to the range's half-width), then the
 * larger. A 1-D transfer function colours all of them alike. Picking the largest only named
 * the bonsai's trunk feature "plate, bottom", after the soil that shares the trunk's values. */
export function structuresAt(mean, list = structures.list) {
  const fit = (s) => {
    const [lo, hi] = s.value_range;
    return Math.abs(mean - 0.5 * (lo + hi)) / Math.max(0.5 * (hi - lo), 0.01);
  };
  return (list || [])
    .filter((s) => s.value_range[0] - 0.02 <= mean && mean <= s.value_range[1] + 0.02)
    .map((s) => ({ s, f: fit(s) }))
    .sort((a, b) => a.f - b.f || b.s.share - a.s.share)
    .map((x) => x.s);
}

/** For each Gaussian, the lower-numbered one it nearly repeats (overlapping values, close
 * colours), or -1: such twins show the same structure twice. */
export function nearTwins(gaussians) {
  return gaussians.map((g, i) => {
    for (let j = 0; j < i; j++) {
      const o = gaussians[j];
      const close = Math.abs(g.mean - o.mean) < 0.5 * (g.width + o.width);
      const dc = Math.max(...[0, 1, 2].map((k) => Math.abs((g.color || [])[k] - (o.color || [])[k])));
      if (close && dc < 0.25) return j;
    }
    return -1;
  });
}

function render(feats) {
  const src = source();
  const tf = src && src.tf;
  const twins = tf ? nearTwins(tf.gaussians) : [];
  if (!feats.length || !tf) {
    strip.replaceChildren(el("p.empty", { text: tf ? "Rendering each feature alone…" : "Each feature of the current result appears here on its own." }));
    markSelection();
    return;
  }
  strip.replaceChildren(
    ...feats.map((f) => {
      const g = tf.gaussians[f.index] || {};
      const on = structuresAt(g.mean ?? 0);
      const what = on.length ? structureName(on[0]) : null;
      const also = on.slice(1).map(structureName);
      const twin = twins[f.index] ?? -1;
      return el(
        `button.feature${twin >= 0 ? ".twin" : ""}`,
        {
          type: "button",
          dataset: { index: String(f.index), structure: what || "", twin: twin >= 0 ? String(twin) : "" },
          title: `Feature ${f.index + 1}${what ? ` (${what})` : ""}${also.length ? `; its values are also those of ${also.join("; ")}` : ""}: mean ${(g.mean ?? 0).toFixed(3)}, width ${(g.width ?? 0).toFixed(3)}, height ${(g.height ?? 0).toFixed(2)}${g.frozen ? " (frozen)" : ""}${twin >= 0 ? `; nearly the same as feature ${twin + 1}` : ""}`,
          "aria-pressed": "false",
          on: { click: () => toggle(f.index) },
        },
        el("img", { src: f.image, alt: `feature ${f.index + 1}`, width: String(TILE), height: String(TILE) }),
        el(
          "span.feature-label",
          {},
          el("span.swatch", { style: { background: rgbToHex(g.color || [0.5, 0.5, 0.5]) } }),
          `${f.index + 1}`,
          what ? el("span.feature-name", { text: what }) : null,
          also.length ? el("span.feature-also", { text: `+${also.length}` }) : null,
          twin >= 0 ? el("span.feature-twin", { text: `≈${twin + 1}` }) : null,
          el("span.feature-val", { text: `@${(g.mean ?? 0).toFixed(2)}` }),
        ),
      );
    }),
  );
  markSelection();
}

function toggle(i) {
  const selected = new Set(state.selected);
  if (selected.has(i)) selected.delete(i);
  else selected.add(i);
  state.follow = false;
  set({ selected });
}

function markSelection() {
  for (const b of strip.querySelectorAll(".feature")) {
    const on = state.selected.has(Number(b.dataset.index));
    b.classList.toggle("selected", on);
    b.setAttribute("aria-pressed", on ? "true" : "false");
  }
  const n = state.selected.size;
  clearBtn.disabled = !n;
  note.textContent = n
    ? `${n} selected: a query refines only ${n === 1 ? "this feature" : "these features"}`
    : "click a feature here (or in the view; Ctrl/⌘-click there adds more) to refine only it";
}
