// Feature decomposition: each Gaussian of the current TF rendered alone, from the volume view's
// camera. Clicking one selects (or deselects) it; the volume view highlights the selection, and
// a query with features selected refines only those.

import * as api from "./api.js";
import { showError } from "./messages.js";
import { el, hexToRgb, on, rgbToHex, set, shownTF, splitQid, state } from "./state.js";
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

function render(feats) {
  const src = source();
  const tf = src && src.tf;
  if (!feats.length || !tf) {
    strip.replaceChildren(el("p.empty", { text: tf ? "Rendering each feature alone…" : "Each feature of the current result appears here on its own." }));
    markSelection();
    return;
  }
  strip.replaceChildren(
    ...feats.map((f) => {
      const g = tf.gaussians[f.index] || {};
      return el(
        "button.feature",
        {
          type: "button",
          dataset: { index: String(f.index) },
          title: `Feature ${f.index + 1}: mean ${(g.mean ?? 0).toFixed(3)}, width ${(g.width ?? 0).toFixed(3)}, height ${(g.height ?? 0).toFixed(2)}${g.frozen ? " (frozen)" : ""}`,
          "aria-pressed": "false",
          on: { click: () => toggle(f.index) },
        },
        el("img", { src: f.image, alt: `feature ${f.index + 1}`, width: String(TILE), height: String(TILE) }),
        el(
          "span.feature-label",
          {},
          el("span.swatch", { style: { background: rgbToHex(g.color || [0.5, 0.5, 0.5]) } }),
          `${f.index + 1}`,
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
