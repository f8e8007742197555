// Messages in the page's corner: errors from the server or a model server, run endings, notes.
// Nothing that goes wrong breaks the page: it becomes one of these.

import { ApiError } from "./api.js";
import { el } from "./state.js";

let box = null;
const live = new Map(); // text → {node, count}

function container() {
  if (!box) box = document.getElementById("toasts");
  return box;
}

/** Show a message; kind is "info", "ok", "warn" or "error". Errors stay until closed. */
export function showMessage(text, { hint = "", kind = "info", timeout } = {}) {
  const key = `${kind}|${text}`;
  const seen = live.get(key);
  if (seen) {
    seen.count += 1;
    seen.badge.textContent = `×${seen.count}`;
    seen.badge.hidden = false;
    return seen.node;
  }
  const badge = el("span.toast-count", { hidden: true });
  const close = el("button.toast-close", { type: "button", "aria-label": "Dismiss", text: "×" });
  const node = el(
    `div.toast.toast-${kind}`,
    { role: kind === "error" ? "alert" : "status", "data-testid": "message" },
    el("div.toast-body", {}, el("div.toast-text", { text }), hint ? el("div.toast-hint", { text: hint }) : null),
    badge,
    close,
  );
  const entry = { node, count: 1, badge };
  live.set(key, entry);
  const remove = () => {
    live.delete(key);
    node.classList.add("leaving");
    setTimeout(() => node.remove(), 180);
  };
  close.addEventListener("click", remove);
  container().append(node);
  const ms = timeout !== undefined ? timeout : kind === "error" ? 0 : kind === "warn" ? 12000 : 5000;
  if (ms > 0) setTimeout(remove, ms);
  while (container().children.length > 6) container().firstElementChild.remove();
  return node;
}

/** Show what went wrong: an ApiError's detail and hint, or any other error's message. */
export function showError(err) {
  if (!err) return;
  if (err instanceof ApiError) {
    showMessage(err.detail, { hint: err.hint, kind: "error" });
    return;
  }
  const text = (err && err.message) || String(err);
  if (/ResizeObserver loop/.test(text)) return; // harmless browser noise
  showMessage(text, { kind: "error" });
}
