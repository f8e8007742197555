// The transfer function over the volume's histogram, and editing it by hand.
//
// Each Gaussian is drawn in its colour over the (log) histogram, the total opacity as a thin
// line, the histogram's materials as ticks. "Edit by hand" gives every Gaussian a handle at its
// peak (drag: mean and height) and two at its flanks (drag: width), and a colour picker for the
// active one; the volume view follows the draft. "Keep" stores the draft as a new point of the
// history (POST /api/edits), to branch from, refine or export like any result.

import * as api from "./api.js";
import { refreshTree, setCurrent } from "./actions.js";
import { showError, showMessage } from "./messages.js";
import { on, rgbToHex, hexToRgb, runVolumeId, set, shownTF, state } from "./state.js";

const PAD = { l: 10, r: 10, t: 10, b: 18 };
const AMBER = "#ffc542";

let canvas;
let ctx;
let readout;
let drag = null;
let histFor = null;

export function initTfEditor() {
  canvas = document.getElementById("tf-canvas");
  ctx = canvas.getContext("2d");
  readout = document.getElementById("tf-readout");

  document.getElementById("edit-toggle").addEventListener("click", startEdit);
  document.getElementById("edit-keep").addEventListener("click", keep);
  document.getElementById("edit-discard").addEventListener("click", () => set({ draft: null }));
  document.getElementById("edit-add").addEventListener("click", addGaussian);
  document.getElementById("edit-remove").addEventListener("click", removeGaussian);
  const color = document.getElementById("edit-color");
  color.addEventListener("input", () => {
    if (!state.draft) return;
    updateGaussian(state.editIndex, { color: hexToRgb(color.value) }, false);
  });

  canvas.addEventListener("pointerdown", onDown);
  canvas.addEventListener("pointermove", onMove);
  canvas.addEventListener("pointerup", onUp);
  canvas.addEventListener("pointerleave", () => {
    if (!drag) canvas.style.setProperty("cursor", "default");
  });

  new ResizeObserver(() => draw()).observe(canvas);
  on(["candidate", "current", "draft", "selected", "histogram", "editIndex", "volumeId"], draw);
  on(["draft", "editIndex", "current"], syncToolbar);
  on(["runDetail", "volumeId"], loadHistogram);
  loadHistogram();
  syncToolbar();
}

// -- the histogram of the volume on view ------------------------------------------------------------
async function loadHistogram() {
  const id = state.run ? runVolumeId() : state.volumeId;
  if (!id || id === histFor) return;
  histFor = id;
  try {
    const h = await api.get(`/api/volumes/${api.enc(id)}/histogram`);
    if (histFor !== id) return;
    set({ histogram: { ...h, volume: id } });
  } catch (err) {
    histFor = null;
    showError(err);
  }
}

// -- drawing -------------------------------------------------------------------------------------------
function geometry() {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  const pw = w - PAD.l - PAD.r;
  const ph = h - PAD.t - PAD.b;
  return {
    w,
    h,
    x: (s) => PAD.l + s * pw,
    y: (o) => PAD.t + (1 - o) * ph,
    s: (px) => (px - PAD.l) / pw,
    o: (py) => 1 - (py - PAD.t) / ph,
  };
}

function gauss(g, s) {
  return g.height * Math.exp(-0.5 * ((s - g.mean) / g.width) ** 2);
}

function rgba(c, a) {
  return `rgba(${Math.round(c[0] * 255)},${Math.round(c[1] * 255)},${Math.round(c[2] * 255)},${a})`;
}

export function draw() {
  if (!canvas || !canvas.clientWidth) return;
  const G = geometry();
  ctx.clearRect(0, 0, G.w, G.h);
  ctx.fillStyle = "#101318";
  ctx.fillRect(0, 0, G.w, G.h);

  // Grid.
  ctx.strokeStyle = "#1f2530";
  ctx.lineWidth = 1;
  for (const o of [0.25, 0.5, 0.75, 1]) {
    ctx.beginPath();
    ctx.moveTo(G.x(0), G.y(o) + 0.5);
    ctx.lineTo(G.x(1), G.y(o) + 0.5);
    ctx.stroke();
  }

  // Histogram (log counts, normalised).
  const h = state.histogram;
  if (h && h.counts && h.counts.length) {
    let counts = h.counts.map((c) => Math.max(0, Number(c) || 0));
    if (Math.max(...counts) > 40) counts = counts.map((c) => Math.log1p(c));
    const max = Math.max(...counts) || 1;
    const n = counts.length;
    ctx.beginPath();
    ctx.moveTo(G.x(0), G.y(0));
    counts.forEach((c, i) => {
      ctx.lineTo(G.x(i / n), G.y((0.92 * c) / max));
      ctx.lineTo(G.x((i + 1) / n), G.y((0.92 * c) / max));
    });
    ctx.lineTo(G.x(1), G.y(0));
    ctx.closePath();
    ctx.fillStyle = "#2c3442";
    ctx.fill();
    ctx.fillStyle = "#6b7486";
    for (const m of h.materials || []) {
      const x = G.x(m.mean);
      ctx.beginPath();
      ctx.moveTo(x, G.y(0) + 1);
      ctx.lineTo(x - 4, G.y(0) + 7);
      ctx.lineTo(x + 4, G.y(0) + 7);
      ctx.closePath();
      ctx.fill();
    }
  }

  // Axis labels: the data range.
  ctx.fillStyle = "#7d8596";
  ctx.font = "10px system-ui, sans-serif";
  const vr = (h && h.value_range) || [0, 1];
  ctx.textBaseline = "bottom";
  ctx.textAlign = "left";
  ctx.fillText(fmtVal(vr[0]), G.x(0), G.h - 2);
  ctx.textAlign = "right";
  ctx.fillText(fmtVal(vr[1]), G.x(1), G.h - 2);
  ctx.textAlign = "center";
  ctx.fillText("value →", G.x(0.5), G.h - 2);

  const tf = shownTF();
  if (!tf) {
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    ctx.fillStyle = "#7d8596";
    ctx.fillText("no transfer function yet", G.w / 2, G.h / 2);
    return;
  }
  const N = 240;
  const gs = tf.gaussians || [];
  gs.forEach((g, i) => {
    const sel = state.selected.has(i) && !state.draft;
    const active = state.draft && i === state.editIndex;
    ctx.beginPath();
    ctx.moveTo(G.x(0), G.y(0));
    for (let k = 0; k <= N; k++) ctx.lineTo(G.x(k / N), G.y(Math.min(1, gauss(g, k / N))));
    ctx.lineTo(G.x(1), G.y(0));
    ctx.closePath();
    ctx.fillStyle = rgba(g.color, sel || active ? 0.45 : 0.26);
    ctx.fill();
    ctx.setLineDash(g.frozen ? [4, 3] : []);
    ctx.lineWidth = sel || active ? 2.5 : 1.5;
    ctx.strokeStyle = sel ? AMBER : rgba(g.color, 1);
    ctx.beginPath();
    for (let k = 0; k <= N; k++) {
      const px = G.x(k / N);
      const py = G.y(Math.min(1, gauss(g, k / N)));
      if (k) ctx.lineTo(px, py);
      else ctx.moveTo(px, py);
    }
    ctx.stroke();
    ctx.setLineDash([]);
  });
  // Total opacity, clamped.
  ctx.beginPath();
  for (let k = 0; k <= N; k++) {
    const s = k / N;
    const o = Math.min(1, gs.reduce((a, g) => a + gauss(g, s), 0));
    if (k) ctx.lineTo(G.x(s), G.y(o));
    else ctx.moveTo(G.x(s), G.y(o));
  }
  ctx.strokeStyle = "rgba(235,238,245,0.55)";
  ctx.lineWidth = 1;
  ctx.stroke();

  // Labels of the Gaussians at their peaks, handles when editing.
  gs.forEach((g, i) => {
    const px = G.x(g.mean);
    const py = G.y(Math.min(1, g.height));
    if (state.draft) {
      const wy = G.y(Math.min(1, g.height * Math.exp(-0.5)));
      for (const sx of [g.mean - g.width, g.mean + g.width]) {
        ctx.fillStyle = "#d7dbe3";
        ctx.fillRect(G.x(sx) - 3.5, wy - 3.5, 7, 7);
      }
      ctx.beginPath();
      ctx.arc(px, py, i === state.editIndex ? 7 : 5.5, 0, Math.PI * 2);
      ctx.fillStyle = rgba(g.color, 1);
      ctx.fill();
      ctx.lineWidth = 2;
      ctx.strokeStyle = i === state.editIndex ? "#ffffff" : "#0b0d11";
      ctx.stroke();
    }
    ctx.fillStyle = state.selected.has(i) && !state.draft ? AMBER : "#aab2c2";
    ctx.font = "10px system-ui, sans-serif";
    ctx.textAlign = "center";
    ctx.textBaseline = "bottom";
    ctx.fillText(String(i + 1), px, Math.max(PAD.t + 9, py - (state.draft ? 8 : 3)));
  });
  canvas.dataset.gaussians = String(gs.length);
}

function fmtVal(v) {
  if (v === null || v === undefined) return "";
  const a = Math.abs(v);
  return a >= 1000 || (a > 0 && a < 0.01) ? v.toExponential(1) : String(Math.round(v * 100) / 100);
}

// -- editing -------------------------------------------------------------------------------------------
function clone(tf) {
  return JSON.parse(JSON.stringify(tf));
}

function startEdit() {
  const tf = shownTF();
  if (!tf) {
    showMessage("There is no transfer function to edit yet.", { kind: "info" });
    return;
  }
  const first = [...state.selected][0];
  set({ editIndex: Number.isInteger(first) ? first : 0, draft: clone(tf) });
}

function updateGaussian(i, changes, dragging) {
  const draft = clone(state.draft);
  Object.assign(draft.gaussians[i], changes);
  state.draftDragging = dragging;
  set({ draft });
}

function addGaussian() {
  if (!state.draft) return;
  const draft = clone(state.draft);
  if (draft.gaussians.length >= 16) {
    showMessage("A transfer function has at most 16 Gaussians.", { kind: "info" });
    return;
  }
  draft.gaussians.push({ mean: 0.5, width: 0.05, height: 0.3, color: [0.8, 0.8, 0.8], frozen: false });
  set({ draft, editIndex: draft.gaussians.length - 1 });
}

function removeGaussian() {
  if (!state.draft) return;
  const draft = clone(state.draft);
  if (draft.gaussians.length <= 1) {
    showMessage("A transfer function needs at least one Gaussian.", { kind: "info" });
    return;
  }
  draft.gaussians.splice(state.editIndex, 1);
  set({ draft, editIndex: Math.max(0, Math.min(state.editIndex, draft.gaussians.length - 1)) });
}

async function keep() {
  if (!state.draft || !state.current) return;
  const btn = document.getElementById("edit-keep");
  btn.disabled = true;
  try {
    const tf = { ...clone(state.draft), name: `hand edit of ${state.current}` };
    const res = await api.post("/api/edits", { parent: state.current, tf });
    set({ draft: null });
    await refreshTree();
    await setCurrent(res.qid, { follow: false });
    showMessage(`Kept your edit as ${res.qid}.`, { kind: "ok" });
  } catch (err) {
    showError(err);
  } finally {
    syncToolbar();
  }
}

function syncToolbar() {
  const editing = Boolean(state.draft);
  document.getElementById("tf-panel").classList.toggle("editing", editing);
  document.getElementById("edit-toggle").hidden = editing;
  for (const id of ["edit-color", "edit-add", "edit-remove", "edit-keep", "edit-discard", "edit-color-label"]) {
    document.getElementById(id).hidden = !editing;
  }
  document.getElementById("edit-keep").disabled = !state.current;
  if (editing) {
    const g = state.draft.gaussians[state.editIndex];
    if (g) document.getElementById("edit-color").value = rgbToHex(g.color);
  }
  showReadout();
}

function showReadout(i = state.editIndex) {
  const tf = shownTF();
  const g = state.draft && tf && tf.gaussians[i];
  if (!g) {
    readout.textContent = state.draft ? "" : tf ? `${tf.gaussians.length} Gaussians` : "";
    return;
  }
  readout.textContent = `#${i + 1} · mean ${g.mean.toFixed(3)} · width ${g.width.toFixed(3)} · height ${g.height.toFixed(2)}`;
}

function hit(e) {
  const G = geometry();
  const r = canvas.getBoundingClientRect();
  const px = e.clientX - r.left;
  const py = e.clientY - r.top;
  const tf = shownTF();
  if (!tf) return { G, px, py, h: null };
  let best = null;
  tf.gaussians.forEach((g, i) => {
    const cand = [
      ["peak", G.x(g.mean), G.y(Math.min(1, g.height))],
      ["left", G.x(g.mean - g.width), G.y(Math.min(1, g.height * Math.exp(-0.5)))],
      ["right", G.x(g.mean + g.width), G.y(Math.min(1, g.height * Math.exp(-0.5)))],
    ];
    for (const [kind, x, y] of cand) {
      const d = Math.hypot(px - x, py - y);
      if (d < 11 && (!best || d < best.d || (d === best.d && i === state.editIndex))) best = { i, kind, d };
    }
  });
  return { G, px, py, h: best };
}

/** The Gaussian that contributes most at the pointer's value (for selection by click). */
function strongestAt(G, px) {
  const tf = shownTF();
  if (!tf) return null;
  const s = G.s(px);
  let best = null;
  tf.gaussians.forEach((g, i) => {
    const v = gauss(g, s);
    if (v > 0.01 && (!best || v > best.v)) best = { i, v };
  });
  return best && best.i;
}

function onDown(e) {
  const { G, px, h } = hit(e);
  if (!state.draft) {
    // Not editing: a click selects (or deselects) the Gaussian strongest at that value.
    const i = strongestAt(G, px);
    if (i === null || i === undefined || !state.candidate) return;
    const selected = new Set(state.selected);
    if (selected.has(i)) selected.delete(i);
    else selected.add(i);
    state.follow = false;
    set({ selected });
    return;
  }
  if (h) {
    canvas.setPointerCapture(e.pointerId);
    drag = h;
    if (h.i !== state.editIndex) set({ editIndex: h.i });
  } else {
    const i = strongestAt(G, px);
    if (i !== null && i !== undefined) set({ editIndex: i });
  }
}

function onMove(e) {
  const { G, px, py, h } = hit(e);
  if (!drag) {
    canvas.style.setProperty("cursor", state.draft && h ? (h.kind === "peak" ? "move" : "ew-resize") : state.draft ? "default" : "pointer");
    return;
  }
  const s = Math.max(0, Math.min(1, G.s(px)));
  const g = state.draft.gaussians[drag.i];
  if (drag.kind === "peak") {
    const o = Math.max(0, Math.min(1, G.o(py)));
    updateGaussian(drag.i, { mean: round3(s), height: round3(o) }, true);
  } else {
    updateGaussian(drag.i, { width: round3(Math.max(0.002, Math.min(0.5, Math.abs(s - g.mean)))) }, true);
  }
  showReadout(drag.i);
}

function onUp() {
  if (!drag) return;
  drag = null;
  state.draftDragging = false;
  set({ draft: state.draft }); // the full frame on release
}

function round3(x) {
  return Math.round(x * 1000) / 1000;
}
