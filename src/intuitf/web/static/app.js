// intuitf in the browser: boots the views, the top bar (volume, live progress) and the export menu.

import * as api from "./api.js";
import { bestOf, previewVolume, readHash, refreshTree, selectRun, setCurrent, startTreePolling } from "./actions.js";
import { initFeatures } from "./features.js";
import { initGallery } from "./gallery.js";
import { initHistory } from "./history.js";
import { showError, showMessage } from "./messages.js";
import { initQuery } from "./query.js";
import { cameraJSON, el, fmtSeconds, fmtUsd, generationOf, on, set, setErrorSink, splitQid, state } from "./state.js";
import { initTfEditor } from "./tf_editor.js";
import { initVolumeView } from "./volume_view.js";

const EXPORTS = [
  ["paraview", "ParaView (.json)"],
  ["slicer", "3D Slicer (.vp)"],
  ["vtk", "VTK (.py/.json)"],
  ["1dt", "ImageVis3D (.1dt)"],
  ["json", "intuitf TF (.json)"],
  ["png", "Rendering, this view (.png)"],
  ["png-judging", "Rendering, the run's judging view (.png)"],
];

async function boot() {
  api.initAuth();
  setErrorSink(showError);
  window.addEventListener("error", (e) => showError(e.error || e.message));
  window.addEventListener("unhandledrejection", (e) => {
    e.preventDefault();
    showError(e.reason);
  });

  initVolumeView();
  initTfEditor();
  initHistory();
  initGallery();
  initFeatures();
  initQuery();
  initTopbar();
  initExport();

  try {
    const [info, volumes] = await Promise.all([api.get("/api/info"), api.get("/api/volumes")]);
    set({ info, volumes });
    document.getElementById("version").textContent = `v${info.version || "?"}`;
  } catch (err) {
    showError(err);
  }
  // What the address names comes first: no volume is previewed before it (a candidate's
  // page never shows another volume while it loads).
  await refreshTree();
  const { qid, run, volume } = readHash();
  const known = (id) => state.volumes.some((v) => v.id === id);
  if (qid && splitQid(qid)) await openCandidate(qid);
  else if (run) await selectRun(run, { follow: true });
  else if (volume && known(volume)) previewVolume(volume);
  else {
    const latest = newestRun(state.tree);
    if (latest) await selectRun(latest.name, { follow: latest.status === "running" });
    else {
      const phantom = state.volumes.find((v) => v.id === "phantom");
      previewVolume((phantom || state.volumes[0] || {}).id || null);
    }
  }
  startTreePolling();
  document.body.classList.add("ready");
}

/** Open candidate `qid` from the address. A reloaded live run whose newest best was on
 * view goes on following its newest best (the address then names it). */
async function openCandidate(qid) {
  const { run } = splitQid(qid);
  await setCurrent(qid, { follow: false });
  const d = state.runDetail;
  if (!d || d.info.name !== run || d.info.status !== "running") return;
  const best = bestOf(run);
  const newest = (q) => generationOf(q) ?? -1;
  if (best && newest(qid) >= newest(best) - 1) await setCurrent(best, { keepRun: true, follow: true });
}

function newestRun(tree) {
  const all = [];
  const walk = (n) => {
    all.push(n.run);
    (n.children || []).forEach(walk);
  };
  (tree || []).forEach(walk);
  all.sort((a, b) => (a.created < b.created ? -1 : a.created > b.created ? 1 : 0));
  return all.find((r) => r.status === "running") || all[all.length - 1] || null;
}

// -- the top bar: volumes and live progress ------------------------------------------------------------
function initTopbar() {
  const select = document.getElementById("volume-select");
  // Choosing a volume leaves the current run: the view previews the volume, and Start
  // begins a run on it (the choice holds while runs go on elsewhere).
  select.addEventListener("change", () => previewVolume(select.value));
  on(["volumes", "volumeId"], () => {
    select.replaceChildren(
      ...state.volumes.map((v) =>
        el("option", { value: v.id, text: `${v.name || v.id} ${v.shape ? `(${v.shape.join("×")})` : ""}` }),
      ),
    );
    if (state.volumeId) select.value = state.volumeId;
  });
  // The picker shows the volume of a run when that run becomes current (once: the details
  // that later refreshes bring never override what a person chose meanwhile).
  let shownFor = null;
  on("run", () => {
    shownFor = null;
  });
  on("runDetail", () => {
    const d = state.runDetail;
    if (!d || shownFor === d.info.name) return;
    shownFor = d.info.name;
    const id = d.volume_id || (state.volumes.find((v) => v.id === d.info.volume || v.name === d.info.volume) || {}).id;
    if (id && id !== state.volumeId && state.volumes.some((v) => v.id === id)) set({ volumeId: id });
  });
  // A file volume's voxel size (a raw file has none), and deleting an upload.
  const spacingField = document.getElementById("volume-spacing-field");
  const spacing = document.getElementById("volume-spacing");
  const del = document.getElementById("volume-delete");
  const syncVolumeTools = () => {
    const v = state.volumes.find((x) => x.id === state.volumeId);
    const previewing = v && !state.run;
    spacingField.hidden = !previewing || v.source === "builtin";
    if (previewing && document.activeElement !== spacing) spacing.value = v.spacing ? v.spacing.join(",") : "";
    del.hidden = !previewing || v.source !== "upload";
  };
  on(["volumes", "volumeId", "run"], syncVolumeTools);
  spacing.addEventListener("change", async () => {
    const id = state.volumeId;
    const text = spacing.value.trim();
    const vals = text ? text.split(/[ ,x×]+/).map(Number) : null;
    if (vals && (vals.length !== 3 || !vals.every((x) => Number.isFinite(x) && x > 0))) {
      showMessage("A spacing is three positive numbers, e.g. 1,1,2.5.", { kind: "warn" });
      return;
    }
    try {
      const v = await api.request("PATCH", `/api/volumes/${api.enc(id)}`, { spacing: vals });
      set({ volumes: state.volumes.map((x) => (x.id === v.id ? v : x)), volumeId: v.id });
      showMessage(vals ? `${v.name}: voxels ${vals.join(" × ")}; new runs of it use this spacing.` : `${v.name}: the file's own spacing.`, { kind: "ok" });
    } catch (err) {
      showError(err);
    }
  });
  del.addEventListener("click", async () => {
    const id = state.volumeId;
    if (!id || !window.confirm(`Delete the uploaded volume ${id}? Its file is removed.`)) return;
    try {
      await api.request("DELETE", `/api/volumes/${api.enc(id)}`, undefined, { raw: true });
      const volumes = state.volumes.filter((x) => x.id !== id);
      set({ volumes });
      previewVolume((volumes.find((v) => v.id === "phantom") || volumes[0] || {}).id || null);
      showMessage(`Deleted ${id}.`, { kind: "ok" });
    } catch (err) {
      showError(err);
    }
  });
  const file = document.getElementById("volume-upload");
  file.addEventListener("change", async () => {
    const f = file.files[0];
    if (!f) return;
    showMessage(`Uploading ${f.name}…`, { kind: "info", timeout: 3000 });
    try {
      const v = await api.upload("/api/volumes", f, f.name);
      set({ volumes: [...state.volumes.filter((x) => x.id !== v.id), v] });
      previewVolume(v.id);
      showMessage(`Loaded ${v.name || v.id}.`, { kind: "ok" });
    } catch (err) {
      showError(err);
    } finally {
      file.value = "";
    }
  });
  on(["runDetail", "progressTick", "live", "serverDown", "volumeId", "run"], renderProgress);
  renderProgress();
}

let lastModelError = null;

function renderProgress() {
  const box = document.getElementById("progress");
  const d = state.runDetail;
  if (!d) {
    const text = state.run
      ? `${state.run}: loading…`
      : state.volumeId
        ? `previewing ${state.volumeId}: Start begins a run on it`
        : "no run yet";
    box.replaceChildren(el("span.muted", { text }));
    box.dataset.status = "";
    return;
  }
  const p = d.progress || {};
  const snap = d.snapshot || {};
  const status = snap.status && snap.status !== "idle" && snap.status !== "ended" ? snap.status : d.info.status;
  const done = p.matches_done || 0;
  const total = p.matches_total || 0;
  const frac = total ? Math.min(1, done / total) : 0;
  const bar = el("span.bar", {}, el("span.bar-fill", { style: { width: `${Math.round(frac * 100)}%` } }));
  const gens = p.generations || snap.generations || d.info.generations || 0;
  const doneGens = Math.max(d.info.generations_done || 0, snap.generation || 0);
  box.dataset.status = status;
  const live = status === "running" || status === "paused" || status === "cancelling";
  const parts = [
    el("span.run-label", { text: d.info.name }),
    el(`span.badge.status-${status}`, { text: status, "data-testid": "run-status" }),
    p.stage || snap.stage ? el("span.kv", {}, el("span.k", { text: "stage" }), el("span.v", { text: p.stage || snap.stage })) : null,
    el("span.kv", { title: "generations done / planned" }, el("span.k", { text: "generations" }), el("span.v", { text: `${doneGens}/${gens || "?"}` })),
    live ? el("span.kv.matches", { title: "matches judged in this generation" }, el("span.k", { text: "matches" }), bar, el("span.v", { text: `${done}/${total || "?"}` })) : null,
    el("span.kv", {}, el("span.k", { text: "calls" }), el("span.v", { text: String(p.calls ?? (d.info.cost || {}).calls ?? 0) })),
    el("span.kv", {}, el("span.k", { text: "cost" }), el("span.v", { text: fmtUsd(p.usd ?? (d.info.cost || {}).usd ?? 0) })),
    live ? el("span.kv", { title: "estimated time left" }, el("span.k", { text: "left" }), el("span.v", { text: fmtSeconds(p.seconds_left) })) : null,
    state.serverDown ? el("span.badge.warn", { text: "server stopped", "data-testid": "server-down" }) : null,
    p.last_error
      ? el("span.badge.warn", { text: "model error", title: p.last_error, "data-testid": "model-error" })
      : null,
    state.live && state.live.run === d.info.name && !state.live.connected && status === "running"
      ? el("span.badge.warn", { text: "reconnecting", title: "The event stream dropped; it reconnects by itself." })
      : null,
  ];
  box.replaceChildren(...parts.filter(Boolean));
  if (p.last_error && p.last_error !== lastModelError) {
    lastModelError = p.last_error;
    showMessage(`The model server: ${p.last_error}`, {
      kind: "warn",
      hint: "Matches it cannot answer stay undecided; check the server, its key or its address.",
    });
  }
}

// -- export ------------------------------------------------------------------------------------------
function initExport() {
  const menu = document.getElementById("export-list");
  const details = document.getElementById("export-menu");
  // The PNG of "this view" is taken from the camera on screen when the item is clicked.
  const urlOf = (qid, to) =>
    to === "png"
      ? `${api.exportUrl(qid, "png")}&camera=${encodeURIComponent(JSON.stringify(cameraJSON()))}`
      : api.exportUrl(qid, to === "png-judging" ? "png" : to);
  const render = () => {
    const qid = state.current;
    details.classList.toggle("disabled", !qid);
    menu.replaceChildren(
      ...EXPORTS.map(([to, label]) =>
        qid
          ? el("a.menu-item", {
              href: urlOf(qid, to),
              download: "",
              "data-to": to,
              text: label,
              on: {
                click: (e) => {
                  e.currentTarget.href = urlOf(qid, to);
                  setTimeout(() => (details.open = false), 0); // the menu closes once chosen
                },
              },
            })
          : el("span.menu-item.disabled", { text: label }),
      ),
    );
  };
  on("current", render);
  render();
}

boot().catch(showError);
