// Talking to the intuitf server: JSON over fetch, uploads, server-sent events, the view socket.
//
// The token comes once with the page's address (?token=…); it is kept in memory and in the
// tab's sessionStorage, removed from the address bar, and sent as `Authorization: token …`.
// Images, downloads, the event stream and the socket rely on the cookie the server set.

let token = null;

export function initAuth() {
  const url = new URL(window.location.href);
  const t = url.searchParams.get("token");
  if (t) {
    token = t;
    try {
      sessionStorage.setItem("intuitf_token", t);
    } catch (_) {
      /* storage may be off: the cookie still works */
    }
    url.searchParams.delete("token");
    window.history.replaceState(null, "", url.pathname + url.search + url.hash);
  } else {
    try {
      token = sessionStorage.getItem("intuitf_token");
    } catch (_) {
      token = null;
    }
  }
}

/** An error the server answered with: {detail, hint} and the HTTP status. */
export class ApiError extends Error {
  constructor(status, detail, hint) {
    super(detail || `HTTP ${status}`);
    this.status = status;
    this.detail = detail;
    this.hint = hint || "";
  }
}

function detailText(d) {
  if (!d) return "";
  if (typeof d === "string") return d;
  if (Array.isArray(d)) {
    // FastAPI validation errors: [{loc, msg}]
    return d
      .map((e) => (e && e.msg ? `${(e.loc || []).slice(1).join(".") || "request"}: ${e.msg}` : String(e)))
      .join("; ");
  }
  return JSON.stringify(d);
}

/** fetch(path) with the token; JSON in and out; non-2xx answers throw ApiError. */
export async function request(method, path, body, { raw = false } = {}) {
  const headers = { Accept: "application/json" };
  if (token) headers.Authorization = `token ${token}`;
  let payload;
  if (body instanceof FormData) payload = body;
  else if (body !== undefined) {
    headers["Content-Type"] = "application/json";
    payload = JSON.stringify(body);
  }
  let res;
  try {
    res = await fetch(path, { method, headers, body: payload, credentials: "same-origin" });
  } catch (err) {
    throw new ApiError(0, "The intuitf server does not answer.", "Is `intuitf serve` still running? Start it again and reload.");
  }
  if (!res.ok) {
    let data = {};
    try {
      data = await res.json();
    } catch (_) {
      data = {};
    }
    let hint = data.hint;
    if (res.status === 401 && !hint) hint = "Open the address that `intuitf serve` printed (it carries the token).";
    throw new ApiError(res.status, detailText(data.detail) || `${res.status} ${res.statusText}`, hint);
  }
  if (raw) return res;
  if (res.status === 204) return null;
  const type = res.headers.get("Content-Type") || "";
  return type.includes("json") ? res.json() : res.blob();
}

export const get = (path) => request("GET", path);
export const post = (path, body = {}) => request("POST", path, body);

/** POST a file (or Blob) as multipart field `file`. */
export function upload(path, file, filename) {
  const fd = new FormData();
  fd.append("file", file, filename || file.name || "upload.bin");
  return request("POST", path, fd);
}

export const enc = encodeURIComponent;

/** URL of a candidate's picture from its run's judging camera. */
export function candidateImageUrl(qid, size) {
  const [run, cid] = qid.split("/");
  return `/api/candidates/${enc(run)}/${enc(cid)}/image?size=${size}`;
}

export function thumbnailUrl(run, generation, best) {
  return `/api/runs/${enc(run)}/generations/${generation}/thumbnail?b=${enc(best || "")}`;
}

export function exportUrl(qid, to) {
  const [run, cid] = qid.split("/");
  return `/api/export/${enc(run)}/${enc(cid)}?to=${enc(to)}`;
}

/**
 * The events of one run as server-sent events. handlers: {event(ev), open(), error()}.
 * Replays from `since` and resumes with Last-Event-ID after a dropped connection; events
 * already seen (by sequence number) are not delivered twice.
 */
export function runEvents(run, since, handlers) {
  let lastSeq = since || 0;
  let source = null;
  let closed = false;
  let retry = null;
  const types = [
    "run_started",
    "stage_started",
    "generation_started",
    "rendered",
    "match_judged",
    "generation_ended",
    "human_verdict",
    "query",
    "status",
    "run_ended",
  ];
  const open = () => {
    if (closed) return;
    source = new EventSource(`/api/runs/${enc(run)}/events?since=${lastSeq}`);
    source.onopen = () => handlers.open && handlers.open();
    const deliver = (msg) => {
      let ev;
      try {
        ev = JSON.parse(msg.data);
      } catch (_) {
        return;
      }
      const seq = ev.seq || parseInt(msg.lastEventId || "0", 10);
      if (seq && seq <= lastSeq) return;
      if (seq) lastSeq = seq;
      if (!ev.type) ev.type = msg.type;
      handlers.event(ev);
    };
    for (const t of types) source.addEventListener(t, deliver);
    source.onmessage = deliver;
    source.onerror = () => {
      handlers.error && handlers.error();
      if (source.readyState === EventSource.CLOSED && !closed) {
        // The browser gave up (an HTTP error): try again a little later, from where we were.
        source = null;
        retry = setTimeout(open, 3000);
      }
    };
  };
  open();
  return {
    close() {
      closed = true;
      clearTimeout(retry);
      if (source) source.close();
    },
    get lastSeq() {
      return lastSeq;
    },
  };
}

/**
 * The volume view's WebSocket: one frame in flight; a request made while one renders replaces
 * the waiting one, so only the newest camera is ever rendered next.
 *
 * onFrame(header, blob) for each image; onError({req, error, hint}) for a refused request.
 */
export class ViewSocket {
  constructor({ onFrame, onError, onStatus }) {
    this.onFrame = onFrame;
    this.onError = onError;
    this.onStatus = onStatus || (() => {});
    this.reqId = 0;
    this.pending = null;
    this.inflight = null;
    this.header = null;
    this.sentAt = 0;
    this.ws = null;
    this.backoff = 500;
    this.stats = { frames: 0, lastMs: 0, lastQuality: "" };
    this.connect();
    this.watchdog = setInterval(() => {
      // A frame that never came (a dropped message) must not freeze the view.
      if (this.inflight && performance.now() - this.sentAt > 20000) {
        this.inflight = null;
        this.pump();
      }
    }, 2000);
  }

  connect() {
    const proto = window.location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(`${proto}://${window.location.host}/api/view`);
    ws.binaryType = "blob";
    this.ws = ws;
    ws.onopen = () => {
      this.backoff = 500;
      this.onStatus("open");
      // A frame lost with the old connection is asked again (newest wins anyway).
      if (this.inflight && !this.pending) this.pending = this.inflight;
      this.inflight = null;
      this.pump();
    };
    ws.onmessage = (msg) => {
      if (typeof msg.data === "string") {
        let j;
        try {
          j = JSON.parse(msg.data);
        } catch (_) {
          return;
        }
        if (j.error) {
          this.inflight = null;
          this.header = null;
          this.onError(j);
          this.pump();
        } else {
          this.header = j;
        }
        return;
      }
      const header = this.header || {};
      this.header = null;
      this.inflight = null;
      this.stats.frames += 1;
      this.stats.lastMs = header.ms;
      this.stats.lastQuality = header.quality;
      this.pump();
      this.onFrame(header, msg.data);
    };
    ws.onclose = () => {
      this.onStatus("closed");
      if (this.closed) return;
      setTimeout(() => this.connect(), this.backoff);
      this.backoff = Math.min(this.backoff * 2, 8000);
    };
  }

  /** Ask for a frame; returns its request number. */
  request(msg) {
    this.reqId += 1;
    this.pending = { ...msg, req: this.reqId };
    this.pump();
    return this.reqId;
  }

  pump() {
    if (this.inflight || !this.pending || !this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    this.inflight = this.pending;
    this.pending = null;
    this.sentAt = performance.now();
    this.ws.send(JSON.stringify(this.inflight));
  }

  get busy() {
    return Boolean(this.inflight || this.pending);
  }

  close() {
    this.closed = true;
    clearInterval(this.watchdog);
    if (this.ws) this.ws.close();
  }
}
