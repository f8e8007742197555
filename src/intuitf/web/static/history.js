// History view: the runs as a tree of stages and generations, one tab per root run.
//
// Each generation is a point with a thumbnail of its best; a run branched from a generation
// (or from one of its candidates) hangs under that point, drawn as a branch. Clicking a point
// makes its best current; "Explore from here" starts a branch from the current candidate.

import * as api from "./api.js";
import { findNode, previewVolume, refreshTree, rootOf, selectRun, setCurrent } from "./actions.js";
import { branchChanges } from "./query.js";
import { showError, showMessage } from "./messages.js";
import { el, fmtRating, fmtUsd, generationOf, on, splitQid, state } from "./state.js";

let tabsEl;
let treeEl;
let branchBtn;
let lastKey = "";

export function initHistory() {
  tabsEl = document.getElementById("history-tabs");
  treeEl = document.getElementById("history-tree");
  branchBtn = document.getElementById("branch-btn");
  branchBtn.addEventListener("click", exploreFromHere);
  on(["tree", "run", "current", "runDetail"], render);
  render();
}

function activeRoot() {
  return (state.run && rootOf(state.run)) || (state.tree && state.tree[state.tree.length - 1]) || null;
}

function render() {
  const root = activeRoot();
  const key = JSON.stringify([state.tree, state.run, state.current, root && root.run.name]);
  branchBtn.disabled = !state.current;
  const cur = splitQid(state.current);
  branchBtn.title = cur ? `Start a new run from ${state.current}` : "Pick a point first";
  if (key === lastKey) return;
  lastKey = key;

  // Tabs: one per root run (a run that is not a branch of another).
  tabsEl.replaceChildren(
    ...(state.tree || []).map((r) =>
      el(
        "button.tab",
        {
          type: "button",
          role: "tab",
          "aria-selected": root && r.run.name === root.run.name ? "true" : "false",
          title: `${r.run.name} · ${r.run.volume} · ${r.run.status}`,
          dataset: { run: r.run.name },
          on: { click: () => selectRun(latestIn(r), { follow: false }) },
        },
        el(`span.dot.status-${r.run.status}`),
        r.run.title || r.run.name,
      ),
    ),
  );

  const activeTab = tabsEl.querySelector('.tab[aria-selected="true"]');
  if (activeTab) {
    // Keep the open tab in sight when the tabs take more rows than the bar shows.
    const top = activeTab.offsetTop; // .tabs is positioned: relative to it
    if (top < tabsEl.scrollTop || top + activeTab.offsetHeight > tabsEl.scrollTop + tabsEl.clientHeight) {
      tabsEl.scrollTop = top - 4;
    }
  }
  const scroll = treeEl.scrollTop;
  if (!root) {
    treeEl.replaceChildren(
      el("p.empty", { text: "No runs yet. Type what you want to see in the query panel and press Start." }),
    );
    return;
  }
  treeEl.replaceChildren(el("div.tree", {}, renderRun(root, 0)));
  treeEl.scrollTop = scroll;
  const here = treeEl.querySelector(".gen.current");
  if (here && here.dataset.scrolled !== state.current) {
    here.scrollIntoView({ block: "nearest" });
    here.dataset.scrolled = state.current;
  }
}

/** The run of a tree that is running, or else the one that was made last. */
function latestIn(root) {
  const all = [];
  const walk = (n) => {
    all.push(n.run);
    n.children.forEach(walk);
  };
  walk(root);
  const running = all.find((r) => r.status === "running");
  if (running) return running.name;
  all.sort((a, b) => (a.created < b.created ? -1 : a.created > b.created ? 1 : 0));
  return all[all.length - 1].name;
}

function intentText(intent) {
  if (!intent) return "";
  if (intent.text) return intent.text;
  return { image: "reference picture", sketch: "sketch", none: "explore", edit: "edit" }[intent.kind] || intent.kind || "";
}

function renderRun(node, depth) {
  const info = node.run;
  const cur = splitQid(state.current);
  const isCurrentRun = state.run === info.name;
  const gens = node.generations || [];
  // Children hang under the generation they branched from.
  const byGen = new Map();
  const loose = [];
  for (const child of node.children || []) {
    const p = child.run.parent || {};
    // From a candidate: under its generation; from "the start of generation g": under g-1.
    const g = p.candidate
      ? generationOf(p.candidate)
      : Number.isInteger(p.generation)
        ? Math.max(0, p.generation - 1)
        : null;
    if (g !== null && gens.some((x) => x.generation === g)) {
      if (!byGen.has(g)) byGen.set(g, []);
      byGen.get(g).push(child);
    } else loose.push(child);
  }

  const head = el(
    "div.run-head",
    {
      title: `${info.name}: ${intentText(info.intent)} · ${info.judge} · ${info.status}`,
      on: { click: () => selectRun(info.name, { follow: info.status === "running" }) },
    },
    el(`span.dot.status-${info.status}`),
    el("span.run-name", { text: info.title || info.name, title: info.title ? `${info.title} (${info.name})` : info.name }),
    info.status !== "completed" ? el(`span.badge.status-${info.status}`, { text: info.status }) : null,
    el("span.run-intent", { text: intentText(info.intent) }),
    el("span.run-meta", {
      text: `${info.generations_done}/${info.generations || "?"} gen · ${fmtUsd((info.cost || {}).usd || 0)}`,
    }),
    isCurrentRun
      ? el(
          "span.run-tools",
          {},
          el("button.btn.tiny", { type: "button", title: "Rename this run", "data-testid": "rename-run", on: { click: (e) => (e.stopPropagation(), renameRun(info)) } }, "Rename"),
          el("button.btn.tiny.danger", { type: "button", title: "Delete this run", "data-testid": "delete-run", disabled: info.status === "running", on: { click: (e) => (e.stopPropagation(), deleteRun(info)) } }, "Delete"),
        )
      : null,
  );

  const list = el("ol.gens");
  let stage = null;
  for (const g of gens) {
    if (g.stage !== stage) {
      stage = g.stage;
      list.append(el(`li.stage-mark.stage-${stage}`, { text: stage }));
    }
    const isCurrent = isCurrentRun && cur && cur.run === info.name && generationOf(cur.cid) === g.generation;
    const item = el(
      `li.gen${isCurrent ? ".current" : ""}`,
      { dataset: { qid: g.qid || "", generation: String(g.generation), run: info.name } },
      el(
        "button.gen-point",
        {
          type: "button",
          title: `${g.qid} · ${g.stage} · rating ${fmtRating(g.rating)}`,
          "aria-label": `generation ${g.generation} of ${info.name}`,
          on: { click: () => g.qid && setCurrent(g.qid, { follow: false }) },
        },
        // The generation's saved picture once written; before that (and for a hand edit,
        // which has none) the candidate rendered on demand: never a request that 404s.
        g.qid || g.thumbnail
          ? el("img.thumb", {
              src: g.thumbnail || api.candidateImageUrl(g.qid, 64),
              alt: `best of generation ${g.generation}`,
              loading: "lazy",
              width: "44",
              height: "44",
            })
          : el("span.thumb.pending", { title: "picture not ready yet" }),
        el(
          "span.gen-meta",
          {},
          el("span.gen-label", { text: `g${g.generation}` }),
          el("span.gen-rating", { text: `rating ${fmtRating(g.rating)}` }),
          matchNote(g.match_stats),
        ),
      ),
    );
    const kids = byGen.get(g.generation);
    if (kids) item.append(el("div.branches", {}, kids.map((k) => renderRun(k, depth + 1))));
    list.append(item);
  }
  if (info.status === "running" && (!info.generations || gens.length < info.generations)) {
    list.append(
      el("li.gen.pending", {}, el("span.spinner"), el("span.gen-label", { text: `g${gens.length} …` })),
    );
  }
  if (!gens.length && info.status !== "running") {
    list.append(el("li.gen.none", { text: info.message || "no generations yet" }));
  }
  return el(
    `div.run-node${isCurrentRun ? ".current-run" : ""}${depth ? ".branch" : ""}`,
    { dataset: { run: info.name } },
    head,
    isCurrentRun ? understood(info) : null,
    list,
    loose.length ? el("div.branches.loose", {}, loose.map((k) => renderRun(k, depth + 1))) : null,
  );
}

/** How the run's intent was read on its volume (words to structures, strokes to values), as
 * a list under the current run's head: a colour on an unexpected part is explained there. */
const understoodClosed = new Set(); // runs whose list the person folded: kept folded on redraw
function understood(info) {
  const lines = info.understood || [];
  if (!lines.length) return null;
  return el(
    "details.run-understood",
    {
      "data-testid": "understood",
      open: !understoodClosed.has(info.name),
      on: { toggle: (e) => (e.target.open ? understoodClosed.delete(info.name) : understoodClosed.add(info.name)) },
    },
    el("summary", { text: "Understood" }),
    el("ul", {}, lines.map((line) => el("li", { text: line }))),
  );
}

async function renameRun(info) {
  const title = window.prompt(`A new name for ${info.title || info.name}:`, info.title || info.name);
  if (!title || !title.trim()) return;
  try {
    await api.post(`/api/runs/${api.enc(info.name)}/rename`, { title: title.trim() });
    await refreshTree();
  } catch (err) {
    showError(err);
  }
}

async function deleteRun(info) {
  if (!window.confirm(`Delete the run ${info.title || info.name}? Its files are moved aside (to .deleted in the runs folder).`)) return;
  // Leave the run first: what the views still ask of it would come back "no run" once
  // it is gone. If the deletion fails, the run is still in the history to choose again.
  if (state.run === info.name) previewVolume(state.volumeId);
  try {
    await api.request("DELETE", `/api/runs/${api.enc(info.name)}`);
    await refreshTree();
    showMessage(`Deleted ${info.title || info.name}.`, { kind: "ok" });
  } catch (err) {
    showError(err);
  }
}

function matchNote(stats) {
  if (!stats) return null;
  const notes = [];
  if (stats.undecided) notes.push(el("span.gen-warn", { title: `${stats.undecided} matches undecided`, text: `${stats.undecided}?` }));
  if (stats.indistinct) {
    notes.push(el("span.gen-warn", { title: "The judge could not tell this generation's candidates apart: its ranking says little.", "data-testid": "indistinct", text: "≈ alike" }));
  }
  return notes.length ? notes : null;
}

/** Start a branch from the current candidate, with the query panel's text if any. */
async function exploreFromHere() {
  const cur = splitQid(state.current);
  if (!cur) return;
  const body = { candidate: cur.cid };
  branchBtn.disabled = true;
  try {
    const changes = await branchChanges();
    if (Object.keys(changes).length) body.changes = changes;
    const res = await api.post(`/api/runs/${api.enc(cur.run)}/branch`, body);
    await refreshTree();
    await selectRun(res.name, { follow: true });
    showMessage(`Branched ${res.name} from ${state.current || cur.cid}.`, { kind: "ok" });
  } catch (err) {
    showError(err);
  } finally {
    branchBtn.disabled = !state.current;
  }
}

export { findNode };
