"""A walk through the paper's three case studies in the browser, as a person does them, with
screenshots to look at (run by tests/web/test_walk_case_studies.py, or by hand)::

    python tests/web/walk_case_studies.py OUT_DIR

1. Bonsai (text, then refine): the volume previewed on its own, its first stage with no
   words, the paper's words ("A potted tree with brown pot, silver branch and golden
   leaves"), a click on the pot and "make it transparent" for only that.
2. Tooth (sketch): a result of the tooth, the paper's strokes drawn over it (red on the
   crown top, yellow on the crown middle, blue on the root), a run from the sketch alone.
3. Foot as reference (picture): the foot with "opaque ivory bone and faint red skin", its
   best picture given as the reference for a head CT, a run from that picture alone.

``INTUITF_WALK_FULL=1`` runs each search at the size of the paper's examples (population 16,
6 generations, 128² pictures) on the volumes at full size, as ``intuitf serve`` loads them,
for screenshots worth looking at; the test runs them small, on volumes downsampled to 64³.

Along the way it checks what a person would notice: the volume choice holds, no request of
the page fails with 404, pending pictures look pending, Undo is disabled with nothing to undo,
the export menu closes after a download, runs can be renamed and deleted.
Real volumes come from ../shared/data/volumes; the test downsamples them (--max-dim) to keep
runs short.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

#: Where the real volumes are (the bonsai, the tooth, the foot).
DATA = Path(
    os.environ.get("INTUITF_DATA_DIR")
    or Path(__file__).resolve().parents[3] / "shared" / "data" / "volumes"
)
CASES = ("bonsai_256x256x256_uint8.raw.gz", "tooth_103x94x161_uint8.raw.gz",
         "foot_zfp8lossy_256x256x256_uint8.raw.gz",
         "ctheadstanford_256x256x113_uint16.raw.gz")  # fmt: skip
SMALL = (
    {"population": "16", "generations": "6", "image_size": "128"}
    if os.environ.get("INTUITF_WALK_FULL")
    else {"population": "6", "generations": "2", "image_size": "64"}
)


def have_data() -> bool:
    return all((DATA / name).is_file() for name in CASES)


class Server:
    """``intuitf serve`` over the case volumes, on a free port: downsampled to at most
    ``max_dim`` voxels per axis, or at full size when ``max_dim`` is None."""

    def __init__(self, root: Path, max_dim: int | None = 64) -> None:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "240", "NO_COLOR": "1"}
        env.pop("INTUITF_TOKEN", None)
        cmd = [sys.executable, "-m", "intuitf", "serve", "--no-browser", "--port", str(port),
               "--runs", str(root / "runs"),
               *(["--max-dim", str(max_dim)] if max_dim else []),
               *[str(DATA / c) for c in CASES]]  # fmt: skip
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, env=env)  # fmt: skip
        self.log: list[str] = []
        self.url = ""
        assert self.proc.stdout is not None
        deadline = time.monotonic() + 120
        while not self.url and time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            self.log.append(line.rstrip())
            m = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[\w-]+)", line)
            if m:
                self.url = m.group(1)
        if not self.url:
            self.stop()
            raise RuntimeError("intuitf serve printed no address:\n" + "\n".join(self.log))
        self.base, self.token = self.url.split("/?token=")
        # The rest of its output goes to serve.log beside the runs (to read after a failure).
        import threading

        def drain(stream, path=root / "serve.log") -> None:
            with open(path, "a", encoding="utf-8") as f:
                for line in stream:
                    f.write(line)
                    f.flush()

        threading.Thread(target=drain, args=(self.proc.stdout,), daemon=True).start()
        while True:
            try:
                self.api("GET", "/api/info")
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)

    def api(self, method: str, path: str):
        import json

        req = urllib.request.Request(self.base + path, method=method)
        req.add_header("Authorization", f"token {self.token}")
        with urllib.request.urlopen(req, timeout=60) as resp:
            raw = resp.read()
            return json.loads(raw) if raw else None

    def get_bytes(self, path: str) -> bytes:
        req = urllib.request.Request(self.base + path)
        req.add_header("Authorization", f"token {self.token}")
        with urllib.request.urlopen(req, timeout=120) as resp:
            return bytes(resp.read())

    def wait_run(self, name: str, timeout: float = 300.0) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            d = self.api("GET", f"/api/runs/{name}")
            if d["info"]["status"] != "running":
                return d
            if time.monotonic() > deadline:
                raise AssertionError(f"{name} still going after {timeout} s")
            time.sleep(0.5)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()


# -- steps ---------------------------------------------------------------------------------------
def state(page, key: str):
    return page.evaluate(f"window.intuitfDebug.state[{key!r}]")


def shot(page, out: Path, name: str) -> None:
    page.screenshot(path=str(out / f"{name}.png"))


def settle_view(page, timeout: float = 120_000) -> None:
    page.wait_for_function(
        "() => { const c = document.getElementById('view-canvas');"
        " return Number(c.dataset.frames || 0) > 0"
        " && !document.getElementById('view-stage').classList.contains('busy'); }",
        timeout=timeout,
    )
    # The Features strip renders each feature alone after the view: a screenshot taken
    # before its tiles load shows "Rendering each feature alone…" instead of them.
    page.wait_for_function(
        "() => { const s = document.getElementById('features-strip');"
        " return !s || (!/Rendering each feature/.test(s.textContent)"
        " && [...s.querySelectorAll('img')].every(i => i.complete)); }",
        timeout=timeout,
    )
    page.wait_for_timeout(800)


def volume_id(page, stem: str) -> str:
    ids = page.eval_on_selector_all("#volume-select option", "os => os.map(o => o.value)")
    return next(i for i in ids if i.startswith(stem))


def choose_volume(page, stem: str) -> str:
    vid = volume_id(page, stem)
    page.select_option("#volume-select", vid)
    page.wait_for_function(
        "v => window.intuitfDebug.state.volumeId === v && !window.intuitfDebug.state.run", arg=vid
    )
    return vid


def small_settings(page) -> None:
    if not page.locator(".q-settings").evaluate("d => d.open"):
        page.click(".q-settings summary")
    for key, value in SMALL.items():
        page.fill(f"#q-{key.replace('_', '-')}", value)


def start_and_wait(page, server: Server, before: str | None, note: dict | None = None) -> str:
    """Press Start and wait for the run to end and fill the gallery. ``note``: a dict that
    gets what the page said while Start waited for the server ("start", None if it said
    nothing) and how long it waited ("seconds")."""
    t0 = time.perf_counter()
    page.click("#q-start")
    if note is not None:
        try:
            note["start"] = page.locator("[data-busy=start]").inner_text(timeout=2_000)
        except Exception:
            note["start"] = None
    try:
        page.wait_for_function(
            "b => { const r = window.intuitfDebug.state.run; return r && r !== b; }",
            arg=before,
            timeout=300_000,
        )
    except Exception:
        said = page.locator("[data-testid=message]").all_inner_texts()
        raise AssertionError(f"Start made no run; the page says {said}") from None
    if note is not None:
        note["seconds"] = time.perf_counter() - t0
    run = state(page, "run")
    server.wait_run(run)
    page.wait_for_function(
        "r => { const d = window.intuitfDebug.state.runDetail;"
        " return d && d.info.name === r && d.info.status !== 'running'; }",
        arg=run,
        timeout=30_000,
    )
    try:
        page.wait_for_selector(f"#gallery-grid .card[data-qid^='{run}/']", timeout=60_000)
    except Exception:
        page.screenshot(path="/tmp/walk-failed.png")
        detail = page.evaluate("JSON.stringify(window.intuitfDebug.state.runDetail).slice(0, 600)")
        raise AssertionError(f"{run}: no results in the gallery; the page has {detail}") from None
    page.wait_for_function(
        "() => [...document.querySelectorAll('#gallery-grid img')]"
        ".every(i => i.complete && i.naturalWidth > 0 && !i.classList.contains('loading'))",
        timeout=120_000,
    )
    return run


def click_view(page, fx: float, fy: float, whole: bool = False) -> str:
    box = page.locator("#view-canvas").bounding_box()
    page.evaluate("document.getElementById('pick-info').textContent = ''")
    at = (box["x"] + fx * box["width"], box["y"] + fy * box["height"])
    if whole:  # the two clicks' note comes first: wait for the double-click's
        page.mouse.dblclick(*at)
        page.wait_for_function(
            "() => /: (all [0-9]+ that make|the only one that makes) this pixel|Nothing/"
            ".test(document.getElementById('pick-info').textContent)"
        )
    else:
        page.mouse.click(*at)
        page.wait_for_function("() => document.getElementById('pick-info').textContent !== ''")
    return page.inner_text("#pick-info")


def pick_something(page, spots, whole: bool = False) -> list[int]:
    """Click (``whole``: double-click) the first of ``spots`` (fractions of the view) that
    shows something; the features selected."""
    for fx, fy in spots:
        text = click_view(page, fx, fy, whole)
        if re.search(r"Selected features? \d", text):
            return sorted(int(i) for i in page.evaluate("[...window.intuitfDebug.state.selected]"))
    raise AssertionError("nothing to pick where the walk clicked")


def walk(browser, server: Server, out: Path) -> dict:
    """The three case studies; returns what was seen (for the test to check)."""
    out.mkdir(parents=True, exist_ok=True)
    seen: dict = {"missing": [], "errors": []}
    ctx = browser.new_context(viewport={"width": 1440, "height": 900}, accept_downloads=True)
    page = ctx.new_page()
    page.set_default_timeout(60_000)
    page.on("pageerror", lambda e: seen["errors"].append(str(e)))
    page.on("response", lambda r: seen["missing"].append(r.url)
            if r.status == 404 and "/api/" in r.url else None)  # fmt: skip
    page.on(
        "dialog", lambda d: d.accept(d.default_value or "") if d.type == "prompt" else d.accept()
    )
    page.goto(server.url)
    page.wait_for_selector("body.ready", timeout=120_000)

    # 1. Bonsai: preview, first stage without words, words, then refine the pot.
    bonsai = choose_volume(page, "bonsai")
    settle_view(page)
    page.wait_for_selector("#features-strip .feature", timeout=120_000)
    page.wait_for_function(
        "() => [...document.querySelectorAll('#features-strip .feature')]"
        ".some(b => b.dataset.structure)",
        timeout=60_000,
    )
    seen["labels"] = page.eval_on_selector_all(
        "#features-strip .feature", "bs => bs.map(b => b.dataset.structure)"
    )
    seen["hint"] = page.inner_text(".view-hint")
    shot(page, out, "1-bonsai-preview")
    small_settings(page)
    first = start_and_wait(page, server, None)
    seen["first_intent"] = server.api("GET", f"/api/runs/{first}")["info"]["intent"]["kind"]
    seen["undo_disabled"] = page.is_disabled("[data-testid=undo]")
    settle_view(page)
    shot(page, out, "1-bonsai-first-stage")
    choose_volume(page, "bonsai")
    page.fill("#q-text", "A potted tree with brown pot, silver branch and golden leaves")
    small_settings(page)
    text_run = start_and_wait(page, server, first)
    seen["volume_held"] = server.api("GET", f"/api/runs/{text_run}")["volume_id"] == bonsai
    settle_view(page)
    shot(page, out, "1-bonsai-text")
    # A double-click on the pot selects every feature that draws it there.
    seen["pot"] = pick_something(
        page, [(0.5, 0.8), (0.5, 0.75), (0.45, 0.85), (0.55, 0.7), (0.5, 0.5)], whole=True
    )
    seen["pot_note"] = page.inner_text("#pick-info")
    shot(page, out, "1-bonsai-pot-selected")
    page.fill("#q-text", "make it transparent")
    refine = start_and_wait(page, server, text_run)
    seen["refine_intent"] = server.api("GET", f"/api/runs/{refine}")["info"]["intent"]["kind"]
    settle_view(page)
    shot(page, out, "1-bonsai-refined")
    # The export menu closes after a download.
    page.click("#export-menu summary")
    with page.expect_download() as dl:
        page.click("#export-list [data-to=json]")
    seen["export_name"] = dl.value.suggested_filename
    page.wait_for_timeout(300)
    seen["export_menu_open"] = page.locator("#export-menu").evaluate("d => d.open")
    # Rename, then delete, the first-stage run.
    page.click(f"#history-tabs .tab[data-run='{first}']")
    page.click(f".run-node[data-run='{first}'] > .run-head")
    page.wait_for_function("r => window.intuitfDebug.state.run === r", arg=first)
    page.click("[data-testid=rename-run]")
    page.wait_for_timeout(500)
    page.click("[data-testid=delete-run]")
    page.wait_for_function(
        'r => !JSON.stringify(window.intuitfDebug.state.tree).includes(`"name":"${r}"`)',
        arg=first,
    )
    seen["deleted"] = first not in [r["name"] for r in server.api("GET", "/api/runs")]
    shot(page, out, "1-bonsai-history")

    # 2. Tooth: a result, then a sketch over it.
    choose_volume(page, "tooth")
    settle_view(page)
    page.fill("#q-text", "the tooth's enamel and dentin")
    small_settings(page)
    tooth = start_and_wait(page, server, refine)
    settle_view(page)
    page.click("#query .seg-kind button[data-kind=sketch]")
    page.click("#sketch-draw")
    settle_view(page)
    box = page.locator("#sketch-canvas").bounding_box()
    # Across the tooth as the view shows it: the crown's top, its middle, the root.
    for color, pts in (("#dc1e1e", [(0.44, 0.27), (0.5, 0.27), (0.56, 0.27)]),
                       ("#f0dc28", [(0.44, 0.36), (0.5, 0.36), (0.56, 0.36)]),
                       ("#2850dc", [(0.46, 0.6), (0.5, 0.6), (0.54, 0.6)])):  # fmt: skip
        page.fill("#sketch-color", color)
        page.mouse.move(box["x"] + pts[0][0] * box["width"], box["y"] + pts[0][1] * box["height"])
        page.mouse.down()
        for x, y in pts[1:]:
            page.mouse.move(box["x"] + x * box["width"], box["y"] + y * box["height"], steps=4)
        page.mouse.up()
    shot(page, out, "2-tooth-sketch")
    page.fill("#q-text", "")
    said: dict = {}
    sketch_run = start_and_wait(page, server, tooth, note=said)
    seen["sketch_start_note"], seen["sketch_start_s"] = said["start"], said["seconds"]
    seen["sketch_intent"] = server.api("GET", f"/api/runs/{sketch_run}")["info"]["intent"]["kind"]
    settle_view(page)
    shot(page, out, "2-tooth-from-sketch")

    # 3. The foot as a radiologist sets it up, then its picture as the reference for a head.
    choose_volume(page, "foot")
    settle_view(page)
    page.click("#query .seg-kind button[data-kind=text]")
    page.fill("#q-text", "opaque ivory bone and faint red skin")
    small_settings(page)
    foot = start_and_wait(page, server, sketch_run)
    settle_view(page)
    shot(page, out, "3-foot")
    qid = page.get_attribute(f"#gallery-grid .card[data-qid^='{foot}/']", "data-qid")
    ref = out / "3-foot-reference-input.png"
    ref.write_bytes(server.get_bytes(f"/api/candidates/{qid}/image?size=256"))
    choose_volume(page, "ctheadstanford")
    # The raw file has no voxel size: its slices are 2 mm apart, its pixels about 1 mm
    # (MANIFEST.md), set in the volume bar as a user would.
    page.fill("#volume-spacing", "1,1,2")
    page.dispatch_event("#volume-spacing", "change")
    page.wait_for_function(
        "() => (window.intuitfDebug.state.volumes.find("
        "v => v.id === window.intuitfDebug.state.volumeId) || {}).spacing?.[2] === 2"
    )
    seen["head_spacing"] = next(v["spacing"] for v in server.api("GET", "/api/volumes")
                                if v["id"].startswith("ctheadstanford"))  # fmt: skip
    # The page's own copy of the volume follows: loaded again with that voxel size.
    page.wait_for_function(
        "() => window.intuitfDebug.gl.ready(window.intuitfDebug.state.volumeId, '1,1,2')",
        timeout=60_000,
    )
    seen["page_spacing"] = page.evaluate("() => window.intuitfDebug.gl.renderer().volume.spacing")
    settle_view(page)
    page.click("#query .seg-kind button[data-kind=image]")
    page.set_input_files("#q-ref", str(ref))
    page.wait_for_selector("#q-ref-preview img")
    page.fill("#q-text", "")
    small_settings(page)
    head = start_and_wait(page, server, foot)
    seen["reference_intent"] = server.api("GET", f"/api/runs/{head}")["info"]["intent"]["kind"]
    settle_view(page)
    shot(page, out, "3-head-from-foot-reference")
    page.wait_for_timeout(1000)
    ctx.close()
    return seen


if __name__ == "__main__":  # pragma: no cover - by hand
    import tempfile

    from playwright.sync_api import sync_playwright

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from helpers.browser import CHROMIUM, CHROMIUM_ARGS

    target = Path(sys.argv[1] if len(sys.argv) > 1 else "walk-shots")
    srv = Server(
        Path(tempfile.mkdtemp()), max_dim=None if os.environ.get("INTUITF_WALK_FULL") else 64
    )
    try:
        with sync_playwright() as pw:
            b = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
            print(walk(b, srv, target))
    finally:
        srv.stop()
