// What the views ask the page to do: make a run or a candidate current, reload what changed,
// and follow the current run's events. The views call these; they never call each other.

import * as api from "./api.js";
import { showError, showMessage } from "./messages.js";
import { set, splitQid, state, generationOf } from "./state.js";

let events = null; // the current run's event stream
let eventsRun = null;
const eventListeners = [];

/** fn(event) for every event of the current run (after the page has handled it). */
export function onRunEvent(fn) {
  eventListeners.push(fn);
}

// -- reloading, coalesced: at most one request in flight, one more queued --------------------
function coalesced(fn, minGap = 250) {
  let running = null;
  let again = false;
  let last = 0;
  const go = async () => {
    if (running) {
      again = true;
      return running;
    }
    const wait = Math.max(0, last + minGap - performance.now());
    running = (async () => {
      if (wait) await new Promise((r) => setTimeout(r, wait));
      try {
        do {
          again = false;
          last = performance.now();
          await fn();
        } while (again);
      } finally {
        running = null;
      }
    })();
    return running;
  };
  return go;
}

export const refreshTree = coalesced(async () => {
  try {
    const tree = await api.get("/api/tree");
    if (JSON.stringify(tree) !== JSON.stringify(state.tree)) set({ tree });
  } catch (err) {
    if (err.status === 0) checkServer();
    else showError(err);
  }
});

export const refreshRun = coalesced(async () => {
  const name = state.run;
  if (!name) return;
  try {
    const detail = await api.get(`/api/runs/${api.enc(name)}`);
    if (state.run !== name) return;
    const was = state.runDetail && state.runDetail.info.name === name ? state.runDetail.info.status : null;
    set({ runDetail: detail });
    if (was !== null && was !== detail.info.status) refreshTree(); // started or ended: the history shows it
  } catch (err) {
    if (err.status === 0) checkServer();
    else if (state.run === name) showError(err);
  }
}, 300);

// -- the current run and candidate -------------------------------------------------------------

/** Make run `name` current; the current candidate becomes `qid`, or the run's best so far. */
export async function selectRun(name, { qid = null, follow = null } = {}) {
  if (!name) return;
  const changed = state.run !== name;
  if (changed) {
    set({ run: name, runDetail: null, marked: [] });
    subscribe(name);
  }
  if (follow !== null) state.follow = follow;
  await refreshRun();
  if (state.run !== name) return;
  const target = qid || (!changed && state.current && splitQid(state.current)?.run === name ? state.current : null) || bestOf(name);
  if (target) await setCurrent(target, { keepRun: true });
  else if (changed) set({ current: null, candidate: null, selected: new Set(), pick: null, draft: null });
  writeHash();
}

/** Show volume `id` on its own, with no run current: the view previews it (a TF on its
 * histogram's materials), a click picks its features, and Start begins a run on it. */
export function previewVolume(id) {
  if (events) {
    events.close();
    events = null;
    eventsRun = null;
  }
  set({
    volumeId: id,
    run: null,
    runDetail: null,
    current: null,
    candidate: null,
    selected: new Set(),
    pick: null,
    draft: null,
    marked: [],
    live: null,
  });
  writeHash();
}

/** The newest best candidate of run `name` (from its details, else the history tree). */
export function bestOf(name) {
  const d = state.runDetail;
  if (d && d.info && d.info.name === name && d.gallery && d.gallery.length) return d.gallery[0].qid;
  const node = findNode(name);
  if (node && node.generations.length) return node.generations[node.generations.length - 1].qid;
  return null;
}

/** Make candidate `qid` ("RUN/gGGG-NNN") current: the views show it. */
export async function setCurrent(qid, { keepRun = false, follow = null } = {}) {
  const parts = splitQid(qid);
  if (!parts) return;
  if (follow !== null) state.follow = follow;
  if (!keepRun && parts.run !== state.run) {
    await selectRun(parts.run, { qid, follow });
    return;
  }
  if (state.current === qid && state.candidate && state.candidate.qid === qid) return;
  set({ current: qid, candidate: null, selected: new Set(), pick: null, draft: null });
  writeHash();
  try {
    const cand = await api.get(`/api/candidates/${api.enc(parts.run)}/${api.enc(parts.cid)}`);
    if (state.current !== qid) return;
    if (!cand.qid) cand.qid = qid;
    set({ candidate: cand });
  } catch (err) {
    // A candidate left meanwhile (its run deleted, another one chosen) is no news.
    if (state.current === qid) showError(err);
  }
}

export function findNode(name, nodes = state.tree) {
  for (const n of nodes || []) {
    if (n.run.name === name) return n;
    const inner = findNode(name, n.children);
    if (inner) return inner;
  }
  return null;
}

export function rootOf(name) {
  for (const r of state.tree || []) if (r.run.name === name || findNode(name, r.children)) return r;
  return null;
}

// -- events ------------------------------------------------------------------------------------
function subscribe(name) {
  if (events && eventsRun === name) return;
  if (events) events.close();
  eventsRun = name;
  set({ live: { run: name, connected: false, last: null } });
  events = api.runEvents(name, 0, {
    open: () => {
      set({ live: { ...state.live, connected: true }, serverDown: false });
    },
    error: () => {
      set({ live: { ...state.live, connected: false } });
      checkServer();
    },
    event: (ev) => handleEvent(name, ev),
  });
}

const reported = new Set();
let checking = false;

/** After a dropped event stream: is the server still there? Say so once if it stopped. */
async function checkServer() {
  if (checking) return;
  checking = true;
  try {
    await api.get("/api/info");
    if (state.serverDown) set({ serverDown: false });
  } catch (err) {
    if (err.status === 0 && !state.serverDown) {
      set({ serverDown: true });
      showMessage("The intuitf server stopped.", {
        kind: "error",
        hint: "Start `intuitf serve` again (same --runs folder) and open its new address: the history is kept.",
      });
    }
  } finally {
    checking = false;
  }
}

function handleEvent(name, ev) {
  if (state.run !== name) return;
  const d = ev.data || {};
  set({ live: { ...state.live, last: ev } });
  const fresh = Date.now() / 1000 - (ev.time || 0) < 30; // a replayed old event is not news
  switch (ev.type) {
    case "match_judged":
      if (state.runDetail && state.runDetail.progress && fresh) {
        const p = state.runDetail.progress;
        if (p.generation === d.generation) p.matches_done = (p.matches_done || 0) + 1;
        set({ progressTick: ev.seq });
      }
      if (d.error && fresh) {
        const key = `${name}:${d.generation}:${String(d.error).slice(0, 60)}`;
        if (!reported.has(key)) {
          reported.add(key);
          showMessage(`The judge could not decide a match: ${d.error}`, {
            kind: "warn",
            hint: "The match counts as undecided; the run goes on. Check the model server if this repeats.",
          });
        }
      }
      refreshRun();
      break;
    case "generation_ended":
      refreshRun().then(() => {
        // Follow the newest best (not while replaying a run's old events after a reload).
        if (state.run === name && state.follow && fresh && d.best) setCurrent(`${name}/${d.best}`, { keepRun: true });
      });
      refreshTree();
      break;
    case "human_verdict":
      refreshRun();
      break;
    case "run_ended":
      refreshRun();
      refreshTree();
      if (fresh) {
        const kind = d.reason === "completed" ? "ok" : d.reason === "cancelled" ? "info" : "error";
        const hints = {
          judge: "The model server failed. Check it, then press Resume run: paid verdicts are kept.",
          budget: "Raise the budget in the query panel, then press Resume run.",
          storage: "Free disk space, then press Resume run.",
        };
        showMessage(`${name}: ${d.message || d.reason}`, { kind, hint: hints[d.reason] || "" });
      }
      break;
    default:
      refreshRun();
      if (ev.type === "run_started" || ev.type === "query" || ev.type === "stage_started") refreshTree();
  }
  for (const fn of eventListeners) {
    try {
      fn(ev);
    } catch (err) {
      console.error(err);
    }
  }
}

// -- the address bar remembers where we are --------------------------------------------------------
export function writeHash() {
  const h = state.current
    ? `#c=${state.current}`
    : state.run
      ? `#run=${state.run}`
      : state.volumeId
        ? `#v=${encodeURIComponent(state.volumeId)}`
        : "";
  if (window.location.hash !== h) window.history.replaceState(null, "", window.location.pathname + window.location.search + h);
}

export function readHash() {
  const h = new URLSearchParams(window.location.hash.slice(1));
  return { qid: h.get("c"), run: h.get("run"), volume: h.get("v") };
}

/** Poll the history while some run (in any tab) is running, so every tab stays current. */
export function startTreePolling() {
  // The current run's details too, while it runs: its end (the folder's lock released just
  // after the last event) and anything a dropped event stream missed.
  setInterval(() => {
    const d = state.runDetail;
    if (d && d.info.status === "running" && document.visibilityState === "visible") refreshRun();
  }, 2000);
  setInterval(() => {
    const anyRunning = JSON.stringify(state.tree).includes('"status":"running"');
    if (anyRunning && document.visibilityState === "visible") refreshTree();
  }, 4000);
}

/** Start a run (a RunSpec) and make it current, following its results. */
export async function startRun(spec) {
  const res = await api.post("/api/runs", spec);
  await refreshTree();
  set({ current: null, candidate: null });
  await selectRun(res.name, { follow: true });
  showMessage(`Started run ${res.name}.`, { kind: "ok" });
  return res.name;
}

export function currentGeneration() {
  return generationOf(state.current);
}
