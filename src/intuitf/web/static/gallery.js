// Recommendation gallery: the top distinct results of the current run's newest generation.
//
// Click a result to make it current; mark two (or more) to compare them side by side, to say
// which is better, or which is best / worst of the marked ones. A person's verdict enters the
// tournament (and can be undone); the judge's reasons for its verdicts on the pair are shown
// beside it.

import * as api from "./api.js";
import { onRunEvent, refreshRun, setCurrent } from "./actions.js";
import { showError, showMessage } from "./messages.js";
import { el, fmtRating, generationOf, on, set, splitQid, state } from "./state.js";

let gridEl;
let headEl;
let barEl;
let dialog;
let verdicts = []; // this page's human verdicts on the current run, newest last
let lastKey = "";

export function initGallery() {
  gridEl = document.getElementById("gallery-grid");
  headEl = document.getElementById("gallery-head");
  barEl = document.getElementById("gallery-actions");
  dialog = document.getElementById("compare-dialog");
  document.getElementById("compare-close").addEventListener("click", () => dialog.close());
  dialog.addEventListener("click", (e) => {
    if (e.target === dialog) dialog.close(); // a click on the backdrop
  });
  on(["runDetail", "current", "marked"], render);
  on("run", () => {
    verdicts = [];
  });
  onRunEvent((ev) => {
    if (ev.type === "human_verdict" && ev.data && ev.data.verdict) {
      const v = ev.data.verdict;
      if (ev.data.action === "added" && !verdicts.some((x) => x.id === v.id)) verdicts.push(v);
      if (ev.data.action !== "added") verdicts = verdicts.filter((x) => x.id !== v.id);
      renderBar();
    }
  });
  render();
}

function items() {
  const d = state.runDetail;
  return (d && d.gallery) || [];
}

function render() {
  const d = state.runDetail;
  const list = items();
  const gen = list.length ? generationOf(list[0].id) : null;
  headEl.textContent = d
    ? list.length
      ? `${d.info.name} · generation ${gen} · top ${list.length}`
      : `${d.info.name} · waiting for the first generation`
    : "no run";
  const key = JSON.stringify([list, state.current, state.marked]);
  if (key !== lastKey) {
    lastKey = key;
    if (!list.length) {
      gridEl.replaceChildren(
        el("p.empty", {
          text: d && d.info.status === "running" ? "The first generation is being judged…" : "Results appear here as each generation ends.",
        }),
      );
    } else {
      gridEl.replaceChildren(...list.map(card));
    }
  }
  renderBar();
}

function card(item) {
  const markIdx = state.marked.indexOf(item.qid);
  const isCurrent = state.current === item.qid;
  const mark = el("input.mark", {
    type: "checkbox",
    title: "Mark to compare or to judge",
    "aria-label": `mark ${item.id}`,
    on: {
      click: (e) => e.stopPropagation(),
      change: () => toggleMark(item.qid),
    },
  });
  mark.checked = markIdx >= 0;
  return el(
    `div.card${isCurrent ? ".current" : ""}${markIdx >= 0 ? ".marked" : ""}`,
    { dataset: { qid: item.qid, rank: String(item.rank) } },
    el(
      "button.card-img",
      {
        type: "button",
        title: `Show ${item.qid}`,
        on: { click: () => setCurrent(item.qid, { follow: false }) },
      },
      pendingImage(api.candidateImageUrl(item.qid, 192), item.id),
      markIdx >= 0 ? el("span.mark-tag", { text: "AB"[markIdx] || String(markIdx + 1) }) : null,
    ),
    el(
      "div.card-meta",
      {},
      el("span.rank", { text: `#${item.rank}` }),
      el("span.rating", { title: "rating", text: fmtRating(item.rating) }),
      el("span.cid", { text: item.id }),
      (item.similar || []).length
        ? el("span.dup-count", { title: `Near-duplicates folded here: ${item.similar.join(", ")}`, "data-testid": "similar", text: `+${item.similar.length}` })
        : null,
      el("label.mark-label", {}, mark),
    ),
  );
}

/** A result's picture that looks pending (striped, "rendering…") until it has loaded: a
 * picture being rendered is not mistaken for an empty, black result. */
function pendingImage(src, alt) {
  const note = el("span.pending-note", { text: "rendering…" });
  const img = el("img.loading", { src, alt, width: "192", height: "192" });
  const done = () => {
    img.classList.remove("loading");
    note.remove();
  };
  img.addEventListener("load", done);
  img.addEventListener("error", () => (note.textContent = "no picture"));
  if (img.complete && img.naturalWidth) done();
  return [img, note];
}

function toggleMark(qid) {
  const marked = state.marked.includes(qid) ? state.marked.filter((q) => q !== qid) : [...state.marked, qid];
  set({ marked });
}

function btn(label, title, fn, enabled, testid) {
  return el(
    "button.btn.small",
    { type: "button", title, disabled: !enabled, "data-testid": testid, on: { click: fn } },
    label,
  );
}

function renderBar() {
  const m = state.marked.filter((q) => items().some((i) => i.qid === q));
  const short = (q) => (splitQid(q) || {}).cid || q;
  const active = verdicts.filter((v) => !v.undone);
  barEl.replaceChildren(
    btn("Compare", "Show the two marked results side by side, with the judge's reasons", () => openCompare(m[0], m[1]), m.length === 2, "compare"),
    btn(
      m.length === 2 ? `${short(m[0])} ≻ ${short(m[1])}` : "A better than B",
      "Say that the first marked result (A) is better than the second (B)",
      () => prefer(m[0], m[1]),
      m.length === 2,
      "prefer",
    ),
    btn("Best of marked", "The first marked is the best of the marked ones", () => bestWorst("best", m[0], m), m.length >= 2, "best"),
    btn("Worst of marked", "The first marked is the worst of the marked ones", () => bestWorst("worst", m[0], m), m.length >= 2, "worst"),
    btn(
      active.length ? `Undo (${active.length})` : "Undo",
      "Take back your last verdict",
      undo,
      Boolean(state.run) && active.length > 0,
      "undo",
    ),
  );
}

async function verdict(path, body, what) {
  try {
    const res = await api.post(`/api/runs/${api.enc(state.run)}/${path}`, body);
    if (res && res.verdict) {
      if (path === "undo") verdicts = verdicts.filter((v) => v.id !== res.verdict.id);
      else if (!verdicts.some((v) => v.id === res.verdict.id)) verdicts.push(res.verdict);
    }
    showMessage(what, { kind: "ok" });
    await refreshRun();
    renderBar();
    return res;
  } catch (err) {
    showError(err);
    return null;
  }
}

export function prefer(better, worse) {
  const b = splitQid(better);
  const w = splitQid(worse);
  if (!b || !w) return null;
  return verdict("prefer", { better: b.cid, worse: w.cid }, `You preferred ${b.cid} over ${w.cid}.`);
}

function bestWorst(kind, which, among) {
  const ids = among.map((q) => splitQid(q).cid);
  const one = splitQid(which).cid;
  return verdict(kind, { [kind]: one, among: ids }, `${one} is the ${kind} of ${ids.length}.`);
}

async function undo() {
  const last = [...verdicts].reverse().find((v) => !v.undone);
  await verdict("undo", last ? { id: last.id } : {}, "Your last verdict was taken back.");
}

// -- compare two side by side ---------------------------------------------------------------
async function openCompare(a, b) {
  if (!a || !b) return;
  const body = document.getElementById("compare-body");
  const side = (qid, label) => {
    const item = items().find((i) => i.qid === qid) || {};
    return el(
      "figure.compare-side",
      { dataset: { qid } },
      el("img", { src: api.candidateImageUrl(qid, 384), alt: qid, width: "384", height: "384" }),
      el("figcaption", {}, el("strong", { text: `${label} · ${splitQid(qid).cid}` }), ` rank #${item.rank ?? "?"} · rating ${fmtRating(item.rating)}`),
      el(
        "div.compare-actions",
        {},
        el("button.btn.small", { type: "button", on: { click: () => setCurrent(qid, { follow: false }) } }, "Make current"),
        el(
          "button.btn.small.primary",
          {
            type: "button",
            "data-testid": `better-${label}`,
            on: { click: () => prefer(qid, qid === a ? b : a).then((r) => r && dialog.close()) },
          },
          `${label} is better`,
        ),
      ),
    );
  };
  const reasons = el("div.reasons", {}, el("p.muted", { text: "Loading the judge's reasons…" }));
  body.replaceChildren(el("div.compare-pair", {}, side(a, "A"), side(b, "B")), reasons);
  dialog.showModal();
  try {
    const g = generationOf(a);
    const matches = await api.get(`/api/runs/${api.enc(state.run)}/matches?generation=${g}`);
    reasons.replaceChildren(...renderReasons(matches, splitQid(a).cid, splitQid(b).cid));
  } catch (err) {
    reasons.replaceChildren(el("p.muted", { text: `The judge's reasons could not be read: ${err.message}` }));
  }
}

function winnerOf(m) {
  if (m.winner === "first") return m.first;
  if (m.winner === "second") return m.second;
  return null;
}

function matchBlock(m, names) {
  const w = winnerOf(m);
  const label = (id) => names[id] || id;
  const reasons = m.reasons || {};
  return el(
    "div.match",
    { dataset: { first: m.first, second: m.second } },
    el(
      "div.match-head",
      {},
      el("span", { text: `${label(m.first)} vs ${label(m.second)}` }),
      el(`span.badge.${m.source === "human" ? "human" : "judge"}`, { text: m.source || "judge" }),
      el("span.match-result", {
        text: m.error ? `undecided: ${m.error}` : w ? `${label(w)} wins${m.p_first !== undefined && m.p_first !== null ? ` (p₁ = ${Number(m.p_first).toFixed(2)})` : ""}` : "tie",
      }),
    ),
    Object.keys(reasons).length
      ? el(
          "dl.match-reasons",
          {},
          Object.entries(reasons).flatMap(([aspect, text]) => [
            el("dt", { text: aspect + (m.per_aspect && m.per_aspect[aspect] ? ` → ${label(m.per_aspect[aspect] === "first" ? m.first : m.per_aspect[aspect] === "second" ? m.second : "tie")}` : "") }),
            el("dd", { text: String(text) }),
          ]),
        )
      : el("p.muted", { text: "No reasons given." }),
  );
}

function renderReasons(matches, a, b) {
  const names = { [a]: `A (${a})`, [b]: `B (${b})` };
  const pair = (matches || []).filter((m) => (m.first === a && m.second === b) || (m.first === b && m.second === a));
  const out = [el("h3", { text: "The judge's verdicts on this pair" })];
  if (pair.length) out.push(...pair.map((m) => matchBlock(m, names)));
  else {
    out.push(el("p.muted", { text: "The judge did not compare these two directly. Their own matches:" }));
    const own = (matches || []).filter((m) => [a, b].includes(m.first) || [a, b].includes(m.second)).slice(0, 6);
    if (own.length) out.push(...own.map((m) => matchBlock(m, names)));
    else out.push(el("p.muted", { text: "No matches recorded for them in this generation." }));
  }
  return out;
}
