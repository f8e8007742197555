// Query view: say what you want (text, a reference picture, a sketch over the rendering), pick
// the evaluator and the budget, and start, pause or stop.
//
// With features selected, Start refines only those (a new branch, POST refine). With none it
// starts a new run (POST /api/runs) or continues the current one with a new customize stage
// (POST query). A sketch is drawn with coloured strokes on a layer over the volume view, shown
// from the run's judging camera, and sent as an RGBA PNG with the current result as its base.

import * as api from "./api.js";
import { refreshRun, refreshTree, selectRun, startRun } from "./actions.js";
import { showError, showMessage } from "./messages.js";
import { el, on, set, shownTF, splitQid, state } from "./state.js";
import { renderSize, resetCamera } from "./volume_view.js";

let kind = "text";
let mode = "new";
let reference = null; // {id, url, name}
let strokes = [];
let stroke = null;
let sketchCanvas;
let sctx;

const $ = (id) => document.getElementById(id);

export function initQuery() {
  for (const b of document.querySelectorAll("#query .seg-kind button")) {
    b.addEventListener("click", () => setKind(b.dataset.kind));
  }
  for (const b of document.querySelectorAll("#query .seg-mode button")) {
    b.addEventListener("click", () => setMode(b.dataset.mode));
  }
  $("q-ref").addEventListener("change", uploadReference);
  $("q-ref-clear").addEventListener("click", () => {
    reference = null;
    $("q-ref").value = "";
    renderReference();
  });
  $("q-start").addEventListener("click", start);
  $("q-evaluator").addEventListener("input", () => {
    $("q-evaluator").dataset.touched = "1";
  });
  $("run-pause").addEventListener("click", pauseOrResume);
  $("run-stop").addEventListener("click", stop);
  $("run-continue").addEventListener("click", continueRun);
  $("q-text").addEventListener("input", syncButtons);
  $("q-text").addEventListener("keydown", (e) => {
    if (e.key === "Enter" && (e.ctrlKey || e.metaKey)) start();
  });

  // The sketch layer over the volume view.
  sketchCanvas = $("sketch-canvas");
  sctx = sketchCanvas.getContext("2d");
  $("sketch-draw").addEventListener("click", () => setSketching(!state.sketching));
  $("sketch-undo").addEventListener("click", () => {
    strokes.pop();
    drawStrokes();
  });
  $("sketch-clear").addEventListener("click", () => {
    strokes = [];
    drawStrokes();
  });
  sketchCanvas.addEventListener("pointerdown", strokeStart);
  sketchCanvas.addEventListener("pointermove", strokeMove);
  sketchCanvas.addEventListener("pointerup", strokeEnd);
  sketchCanvas.addEventListener("pointercancel", strokeEnd);
  new ResizeObserver(drawStrokes).observe(sketchCanvas);

  on(["info"], fillEvaluators);
  on(["run", "runDetail", "selected", "current", "volumeId"], syncButtons);
  on(["current"], () => {
    if (state.sketching && !state.current) setSketching(false);
  });
  setKind("text");
  setMode("new");
  syncButtons();
}

function fillEvaluators() {
  const info = state.info || {};
  const list = $("q-evaluators");
  list.replaceChildren(...(info.evaluators || ["metric"]).map((e) => el("option", { value: e })));
  if (!$("q-evaluator").value) $("q-evaluator").value = info.evaluator || "metric";
}

function setKind(k) {
  kind = k;
  for (const b of document.querySelectorAll("#query .seg-kind button")) {
    b.setAttribute("aria-pressed", b.dataset.kind === k ? "true" : "false");
  }
  $("q-pane-image").hidden = k !== "image";
  $("q-pane-sketch").hidden = k !== "sketch";
  $("q-text").placeholder =
    k === "text"
      ? "What do you want to see? e.g. opaque ivory bone, faint red skin"
      : k === "image"
        ? "Optional: say what to take from the picture"
        : "Optional: say what the strokes mean";
  if (k !== "sketch" && state.sketching) setSketching(false);
  document.getElementById("view-stage").classList.toggle("show-sketch", k === "sketch");
  syncButtons();
}

function setMode(m) {
  mode = m;
  for (const b of document.querySelectorAll("#query .seg-mode button")) {
    b.setAttribute("aria-pressed", b.dataset.mode === m ? "true" : "false");
  }
  syncButtons();
}

function num(id) {
  const v = $(id).value.trim();
  if (!v) return undefined;
  const x = Number(v);
  return Number.isFinite(x) ? x : undefined;
}

function runLive() {
  const d = state.runDetail;
  if (!d) return false;
  const snap = d.snapshot;
  if (snap && (snap.status === "running" || snap.status === "paused" || snap.status === "cancelling")) return true;
  if (snap && snap.status === "idle" && !snap.ended && d.info.status === "running") return true;
  return d.info.status === "running" && !(snap && snap.status === "ended");
}

function syncButtons() {
  const d = state.runDetail;
  const live = runLive();
  const paused = d && d.snapshot && d.snapshot.status === "paused";
  $("run-pause").disabled = !live;
  $("run-pause").textContent = paused ? "Resume" : "Pause";
  $("run-stop").disabled = !live || (d.snapshot && d.snapshot.status === "cancelling");
  const resumable = d && !live && ["stopped", "cancelled", "budget", "judge", "interrupted", "storage", "new"].includes(d.info.status);
  $("run-continue").hidden = !resumable;

  const modeCont = document.querySelector('#query .seg-mode button[data-mode="continue"]');
  modeCont.disabled = !state.run;
  modeCont.textContent = state.run ? `a new stage of ${state.run}` : "a new stage of the run";
  if (!state.run && mode === "continue") setMode("new");

  const n = state.selected.size;
  const startBtn = $("q-start");
  $("q-refine-note").hidden = !n;
  $("q-refine-note").textContent = n ? `Refining ${n} selected feature${n > 1 ? "s" : ""} of ${state.current}: only ${n > 1 ? "they change" : "it changes"}.` : "";
  const words = $("q-text").value.trim();
  startBtn.textContent = n ? `Refine ${n} feature${n > 1 ? "s" : ""}` : mode === "continue" && state.run ? "Continue with this query" : "Start";
  startBtn.title =
    !n && mode === "new" && kind === "text" && !words
      ? "With no words: find the volume's structures first (quality only); say what you want later"
      : "";
  if (n && !state.current && !state.run) $("q-refine-note").textContent = `Refining ${n} selected feature${n > 1 ? "s" : ""} of the preview in a new run: only ${n > 1 ? "they change" : "it changes"}.`;
  $("sketch-draw").disabled = !state.current;
  $("sketch-draw").textContent = state.sketching ? "Done drawing" : "Draw on the rendering";
}

// -- the reference picture ------------------------------------------------------------------------
async function uploadReference() {
  const file = $("q-ref").files[0];
  if (!file) return;
  try {
    const res = await api.upload("/api/uploads", file, file.name);
    if (reference && reference.url) URL.revokeObjectURL(reference.url);
    reference = { id: res.id, url: URL.createObjectURL(file), name: file.name, width: res.width, height: res.height };
  } catch (err) {
    reference = null;
    $("q-ref").value = "";
    showError(err);
  }
  renderReference();
}

function renderReference() {
  const box = $("q-ref-preview");
  $("q-ref-clear").hidden = !reference;
  box.replaceChildren(
    reference
      ? el("img", { src: reference.url, alt: reference.name, title: `${reference.name} (${reference.width}×${reference.height})`, "data-upload": reference.id })
      : el("span.muted", { text: "no picture" }),
  );
}

// -- the sketch ---------------------------------------------------------------------------------------
function setSketching(on) {
  if (on && !state.current) {
    showMessage("A sketch is drawn over a result: start a run or pick a result first.", { kind: "info" });
    return;
  }
  if (on) resetCamera(); // the base is the result from the run's judging camera
  set({ sketching: on });
  document.getElementById("view-stage").classList.toggle("sketching", on);
  syncButtons();
  drawStrokes();
}

function pos(e) {
  const r = sketchCanvas.getBoundingClientRect();
  return [(e.clientX - r.left) / r.width, (e.clientY - r.top) / r.height];
}

function strokeStart(e) {
  if (!state.sketching) return;
  sketchCanvas.setPointerCapture(e.pointerId);
  stroke = { color: $("sketch-color").value, width: Number($("sketch-width").value) / 400, points: [pos(e)] };
  strokes.push(stroke);
  drawStrokes();
}

function strokeMove(e) {
  if (!stroke) return;
  const events = e.getCoalescedEvents ? e.getCoalescedEvents() : [e];
  for (const ce of events.length ? events : [e]) stroke.points.push(pos(ce));
  drawStrokes();
}

function strokeEnd() {
  stroke = null;
  $("sketch-count").textContent = strokes.length ? `${strokes.length} stroke${strokes.length > 1 ? "s" : ""}` : "";
}

function paint(ctx, w, h) {
  ctx.clearRect(0, 0, w, h);
  ctx.lineCap = "round";
  ctx.lineJoin = "round";
  for (const s of strokes) {
    ctx.strokeStyle = s.color;
    ctx.fillStyle = s.color;
    ctx.lineWidth = Math.max(1, s.width * w);
    if (s.points.length === 1) {
      ctx.beginPath();
      ctx.arc(s.points[0][0] * w, s.points[0][1] * h, ctx.lineWidth / 2, 0, Math.PI * 2);
      ctx.fill();
      continue;
    }
    ctx.beginPath();
    s.points.forEach(([x, y], i) => (i ? ctx.lineTo(x * w, y * h) : ctx.moveTo(x * w, y * h)));
    ctx.stroke();
  }
}

function drawStrokes() {
  if (!sketchCanvas) return;
  const dpr = window.devicePixelRatio || 1;
  const w = Math.round(sketchCanvas.clientWidth * dpr);
  const h = Math.round(sketchCanvas.clientHeight * dpr);
  if (w && (sketchCanvas.width !== w || sketchCanvas.height !== h)) {
    sketchCanvas.width = w;
    sketchCanvas.height = h;
  }
  paint(sctx, sketchCanvas.width, sketchCanvas.height);
  sketchCanvas.dataset.strokes = String(strokes.length);
  $("sketch-count").textContent = strokes.length ? `${strokes.length} stroke${strokes.length > 1 ? "s" : ""}` : "";
}

/** The strokes as an RGBA PNG (transparent where nothing was drawn), at the view's size. */
function sketchBlob() {
  const size = renderSize();
  const off = document.createElement("canvas");
  off.width = size;
  off.height = size;
  paint(off.getContext("2d"), size, size);
  return new Promise((resolve) => off.toBlob(resolve, "image/png"));
}

// -- start, pause, stop ---------------------------------------------------------------------------
async function intentFromPanel(text, { firstStage = false } = {}) {
  if (kind === "text") {
    // No words on a new run: the paper's first stage (quality only, to find the structures);
    // words come later, as a new stage or a refinement of the features found.
    if (!text && firstStage) return { kind: "none" };
    if (!text) throw new UserError("Type what you want to see first.");
    return { kind: "text", text };
  }
  if (kind === "image") {
    if (!reference) throw new UserError("Choose a reference picture first.");
    return { kind: "image", reference: `upload:${reference.id}`, ...(text ? { text } : {}) };
  }
  if (!strokes.length) throw new UserError("Draw on the rendering first (Draw on the rendering, then drag).");
  if (!state.current) throw new UserError("A sketch needs a result to draw on.");
  const blob = await sketchBlob();
  const up = await api.upload("/api/uploads", blob, "sketch.png");
  return { kind: "sketch", sketch: `upload:${up.id}`, base: `candidate:${state.current}`, ...(text ? { text } : {}) };
}

class UserError extends Error {}

/** What "Explore from here" takes from this panel: the query (text, picture or sketch; none
 * when the panel is empty), the settings typed in and the evaluator. */
export async function branchChanges() {
  const text = $("q-text").value.trim();
  const changes = {};
  const empty = kind === "text" ? !text : kind === "image" ? !reference : !strokes.length;
  if (!empty) changes.intent = await intentFromPanel(text);
  const s = settings();
  if (Object.keys(s).length) changes.settings = s;
  if ($("q-evaluator").dataset.touched && $("q-evaluator").value.trim()) changes.judge = judgeSpec();
  return changes;
}

function judgeSpec() {
  const judge = { spec: $("q-evaluator").value.trim() || "metric" };
  const usd = num("q-budget-usd");
  const calls = num("q-budget-calls");
  if (usd !== undefined) judge.budget_usd = usd;
  if (calls !== undefined) judge.budget_calls = Math.round(calls);
  return judge;
}

function settings() {
  const s = {};
  for (const [id, key] of [
    ["q-population", "population"],
    ["q-generations", "generations"],
    ["q-image-size", "image_size"],
  ]) {
    const v = num(id);
    if (v !== undefined) s[key] = Math.round(v);
  }
  return s;
}

async function start() {
  const btn = $("q-start");
  const text = $("q-text").value.trim();
  btn.disabled = true;
  // The server answers once the run is set up, and a sketch's strokes are fitted to the
  // volume first (seconds on a real volume): say so while the button waits.
  let fitting = false;
  let note = null;
  const slow = setTimeout(() => {
    note = showMessage(
      fitting ? "Fitting the sketch's colours to the volume; the run starts right after…" : "Starting…",
      { kind: "info", timeout: 0 },
    );
    note.dataset.busy = "start";
  }, 500);
  try {
    const cur = splitQid(state.current);
    const preview = !state.run && !cur && shownTF();
    if (state.selected.size && preview) {
      // Features picked on a volume's preview: a run that refines only those, from the preview.
      if (!text) throw new UserError("Say what should change about the selected features (e.g. “make it transparent”).");
      const selected = [...state.selected].sort((a, b) => a - b);
      const s = settings();
      await startRun({
        volume: state.volumeId,
        intent: { kind: "edit", text, selected },
        initial: [preview],
        judge: judgeSpec(),
        settings: s,
      });
    } else if (state.selected.size && cur) {
      if (!text) throw new UserError("Say what should change about the selected features (e.g. “make it transparent”).");
      const body = { candidate: cur.cid, selected: [...state.selected].sort((a, b) => a - b), text };
      const g = num("q-generations");
      if (g !== undefined) body.generations = Math.round(g);
      const res = await api.post(`/api/runs/${api.enc(cur.run)}/refine`, body);
      await refreshTree();
      await selectRun(res.name, { follow: true });
      showMessage(`Refining ${body.selected.map((i) => i + 1).join(", ")} of ${cur.run}/${cur.cid} in ${res.name}.`, { kind: "ok" });
    } else if (mode === "continue" && state.run) {
      const intent = await intentFromPanel(text);
      fitting = intent.kind === "sketch";
      const body = { intent };
      const g = num("q-generations");
      if (g !== undefined) body.generations = Math.round(g);
      await api.post(`/api/runs/${api.enc(state.run)}/query`, body);
      state.follow = true;
      await refreshRun();
      await refreshTree();
      showMessage(`${state.run} goes on with your query.`, { kind: "ok" });
    } else {
      if (!state.volumeId) throw new UserError("Choose a volume first (top left).");
      const intent = await intentFromPanel(text, { firstStage: true });
      fitting = intent.kind === "sketch";
      await startRun({ volume: state.volumeId, intent, judge: judgeSpec(), settings: settings() });
    }
    if (state.sketching) setSketching(false);
  } catch (err) {
    if (err instanceof UserError) showMessage(err.message, { kind: "warn" });
    else showError(err);
  } finally {
    clearTimeout(slow);
    if (note) note.querySelector(".toast-close").click();
    btn.disabled = false;
    syncButtons();
  }
}

async function pauseOrResume() {
  if (!state.run) return;
  const paused = state.runDetail && state.runDetail.snapshot && state.runDetail.snapshot.status === "paused";
  try {
    await api.post(`/api/runs/${api.enc(state.run)}/${paused ? "proceed" : "pause"}`);
    showMessage(paused ? `${state.run} goes on.` : `${state.run} pauses after the match in progress.`, { kind: "info" });
    await refreshRun();
  } catch (err) {
    showError(err);
  }
}

async function stop() {
  if (!state.run) return;
  try {
    await api.post(`/api/runs/${api.enc(state.run)}/cancel`);
    showMessage(`Stopping ${state.run}; what it has done is kept.`, { kind: "info" });
    await refreshRun();
  } catch (err) {
    showError(err);
  }
}

async function continueRun() {
  if (!state.run) return;
  const body = {};
  const j = judgeSpec();
  if (j.budget_usd !== undefined) body.budget_usd = j.budget_usd;
  if (j.budget_calls !== undefined) body.budget_calls = j.budget_calls;
  if ($("q-evaluator").dataset.touched && $("q-evaluator").value.trim()) {
    body.evaluator = $("q-evaluator").value.trim();
  }
  try {
    await api.post(`/api/runs/${api.enc(state.run)}/continue`, body);
    state.follow = true;
    showMessage(`${state.run} continues.`, { kind: "ok" });
    await refreshRun();
    await refreshTree();
  } catch (err) {
    showError(err);
  }
}
