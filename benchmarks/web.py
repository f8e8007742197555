"""The volume view in the browser: the page's own WebGL2 frames, pick and first picture, and the
server's stills, on a real volume (the bonsai by default).

Run: ``python benchmarks/web.py`` (options: ``--volume ID``, ``--data DIR`` (default
``$INTUITF_DATA`` or ``../shared/data/volumes``), ``--frames N``, ``--stills N``,
``--quick``, ``--gl swiftshader|llvmpipe``). A real ``intuitf serve`` app runs in its own
process on a free loopback port; this process drives headless Chromium (Debian's
``chromium``, Playwright) against it and asks the server for stills over the view socket.

Every frame and still is from the view a person gets: the volume's own camera (upright,
chosen for it: ``GET /api/volumes/{id}/camera``, the view its runs judge from), turning.
Until this view was in the page, the frames were measured from the page's default camera,
which looks at the bonsai from below, where the opaque pot ends most rays early: about three
times cheaper than the side view a person sees.

Measured, with the browser's own clock (``performance.now`` around a draw that waits for its
pixels):

- **first picture**: from choosing the volume in the page's picker to its first full frame
  (texture fetched, block ranges computed, uploaded, shader compiled, drawn);
- **frames while dragging**: the page's renderer drawing the current TF at 256² and 512², the
  camera turning 4° a frame (as a drag does), shaded, median / p90; and the frames the page
  itself drew during a real mouse drag of the view (their side: in software only, the page
  lowers it when a frame is over its budget, and says so on screen);
- **after a hand edit**: a Gaussian's height and colour changed, then a frame (the LUT and the
  block visibility rebuilt, then drawn);
- **click → outline**: a click on the view to the selection's outline on screen (the page's
  attribution pass on the GPU, the smallest-area rule, the outline drawn);
- **shader cost per sample**: a TF that keeps every sample visible and never ends a ray early,
  so every ray walks its whole length; the sample count comes from the server's
  ``kernels.count_samples`` for the same camera (same rays, same step);
- **server stills**: 256² and 512² shaded, the server's own render time (frame header
  ``render_ms``), no run going.

Headless Chromium here renders WebGL2 in software on the machine's cores: SwiftShader by
default (``--disable-gpu``, as the tests run it), or Mesa's llvmpipe with ``--gl llvmpipe``
(the same shader at about 40 % of SwiftShader's cost per sample here). Either way its figures
bound any GPU's from above. The cost per sample lets one estimate a GPU: a laptop GPU does on
the order of 10⁹–10¹⁰ samples a second where SwiftShader does about 10⁸.

Targets on the 2-core reference machine, in software: 256² frame ≤ 200 ms, 512² ≤ 600 ms,
click → outline ≤ 300 ms, first picture ≤ 3 s; server 512² shaded still ≤ 500 ms idle.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
]
#: The software renderers Chromium can draw WebGL2 with here: SwiftShader (what it uses with
#: ``--disable-gpu``, the tests' setting; the Subzero JIT, 4-wide) and Mesa's llvmpipe through
#: ANGLE's EGL backend (LLVM, 8-wide: the software renderer a Linux desktop without a GPU
#: driver has). Neither is a GPU: both bound its figures from above.
GL_ARGS = {
    "swiftshader": ["--disable-gpu"],
    "llvmpipe": ["--use-angle=gl-egl", "--ignore-gpu-blocklist"],
}
DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "volumes"


def serve(port: int, runs: str, token: str, data: str | None) -> None:
    """The server process: the app as ``intuitf serve`` runs it, on ``port``."""
    from intuitf.web.app import create_app, make_server

    app = create_app(runs, [], data or None, token=token,
                     allowed_hosts=[f"127.0.0.1:{port}", f"localhost:{port}"])  # fmt: skip
    make_server(app, "127.0.0.1", port).run()


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    v = sorted(values)
    k = (len(v) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


def server_stills(ws_url: str, target: dict, size: int, n: int, camera: dict) -> list[float]:
    """The server's render time (ms) of ``n`` full shaded stills at ``size``² (after one
    warm-up), from ``camera`` turning 7° a still."""
    from websockets.sync.client import connect

    out = []
    with connect(ws_url, open_timeout=30, max_size=None) as ws:
        for i in range(n + 1):
            req = {"req": i, "target": target, "size": size, "shaded": True,
                   "background": [0, 0, 0], "quality": "full",
                   "camera": {**camera, "azimuth": camera["azimuth"] + 7 * i}}  # fmt: skip
            ws.send(json.dumps(req))
            head = json.loads(ws.recv(timeout=120))
            if "error" in head:
                raise RuntimeError(head)
            ws.recv(timeout=120)
            if i:
                out.append(float(head["render_ms"]))
    return out


#: In the page: the renderer drawing the current TF from turning cameras at one size.
FRAMES_JS = """async ({size, n, shading}) => {
  const g = window.intuitfDebug.gl.renderer();
  await g.gradientReady;  // shaded frames use the gradient texture once it is built
  const S = await import('/static/state.js');
  const tf = S.shownTF();
  const cam = {...window.intuitfDebug.state.camera, pan: [0, 0]};
  g.render({tf, camera: cam, width: size, height: size, shading});  // warm
  const ms = [];
  for (let i = 0; i < n; i++) {
    cam.azimuth = (cam.azimuth + 4) % 360;
    ms.push(g.render({tf, camera: cam, width: size, height: size, shading}));
  }
  return ms;
}"""

#: In the page: a hand edit (height and colour of one Gaussian), then one frame, n times.
EDIT_JS = """async ({size, n}) => {
  const g = window.intuitfDebug.gl.renderer();
  await g.gradientReady;  // shaded frames use the gradient texture once it is built
  const S = await import('/static/state.js');
  const base = S.shownTF();
  const cam = {...window.intuitfDebug.state.camera, pan: [0, 0]};
  const ms = [];
  for (let i = 0; i < n; i++) {
    const tf = JSON.parse(JSON.stringify(base));
    const k = i % tf.gaussians.length;
    tf.gaussians[k].height = Math.min(1, tf.gaussians[k].height * (1.1 + 0.05 * i));
    tf.gaussians[k].color = [0.2 + 0.05 * i % 0.8, 0.5, 0.9];
    const t0 = performance.now();
    g.render({tf, camera: cam, width: size, height: size, shading: true});
    ms.push(performance.now() - t0);
  }
  return ms;
}"""

#: In the page: every sample visible, no early end; the frame's time.
DENSE_JS = """async ({size, shading, camera}) => {
  const g = window.intuitfDebug.gl.renderer();
  await g.gradientReady;  // shaded frames use the gradient texture once it is built
  const tf = {gaussians: [{mean: 0.5, width: 0.5, height: 0.001, color: [0.8, 0.8, 0.8]}]};
  g.render({tf, camera, width: size, height: size, shading});
  const ms = [];
  for (let i = 0; i < 3; i++) ms.push(g.render({tf, camera, width: size, height: size, shading}));
  ms.sort((a, b) => a - b);
  return ms[1];
}"""


def samples_on_rays(volume_path: Path, camera: dict, size: int) -> int:
    """How many samples the rays of ``camera`` at ``size``² take (the server's count)."""
    import numpy as np

    from intuitf.render import Camera, VolumeRenderer, kernels
    from intuitf.volume import load_volume

    r = VolumeRenderer(load_volume(volume_path), size=size, device="cpu")
    counts = np.zeros(size * size, dtype=np.int64)
    dims = np.asarray(r.volume.dims, dtype=np.int64)
    frame = r.frame(Camera.from_dict(camera)).packed()
    kernels.count_samples(frame, r._spacing, dims, r.sample_distance, counts)
    return int(counts.sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--volume", default="bonsai", help="volume id (default: bonsai)")
    ap.add_argument("--data", default=os.environ.get("INTUITF_DATA") or str(DEFAULT_DATA),
                    help="folder of volumes to offer")  # fmt: skip
    ap.add_argument("--frames", type=int, default=12, help="page frames per measurement")
    ap.add_argument("--stills", type=int, default=6, help="server stills per size")
    ap.add_argument("--quick", action="store_true", help="few frames and stills")
    ap.add_argument("--gl", choices=sorted(GL_ARGS), default="swiftshader",
                    help="Chromium's software WebGL2 renderer (default: swiftshader)")  # fmt: skip
    ap.add_argument("--shots", default=None, help="folder for screenshots of the page")
    ap.add_argument("--serve", nargs=4, metavar=("PORT", "RUNS", "TOKEN", "DATA"),
                    help=argparse.SUPPRESS)  # fmt: skip
    args = ap.parse_args()
    if args.serve:
        port, runs, token, data = args.serve
        serve(int(port), runs, token, None if data == "-" else data)
        return
    if args.quick:
        args.frames, args.stills = 4, 2
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("benchmarks/web.py needs Debian's chromium on PATH")

    load_before = os.getloadavg()
    port, token = free_port(), "bench-token"
    runs = tempfile.mkdtemp(prefix="intuitf-web-bench-")
    server = subprocess.Popen(
        [sys.executable, __file__, "--serve", str(port), runs, token, args.data or "-"],
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    base = f"http://127.0.0.1:{port}"
    ws_url = f"ws://127.0.0.1:{port}/api/view?token={token}"
    res: dict = {}
    try:
        with httpx.Client(base_url=base, headers={"Authorization": f"token {token}"},
                          timeout=120) as c:  # fmt: skip
            deadline = time.monotonic() + 60
            while True:
                try:
                    if c.get("/api/info").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline or server.poll() is not None:
                    raise SystemExit("the server did not start")
                time.sleep(0.1)
            vols = {v["id"]: v for v in c.get("/api/volumes").json()}
            if args.volume not in vols:
                raise SystemExit(f"no volume {args.volume!r}: the server offers {sorted(vols)}")
            hist = c.get(f"/api/volumes/{args.volume}/histogram").json()
        res.update(browser_part(base, token, args, chromium, hist))
        target = {"volume": args.volume, "tf": res.pop("tf")}
        for size in (256, 512):
            res[f"server {size}"] = server_stills(ws_url, target, size, args.stills,
                                                  res["camera"])  # fmt: skip
        volume_path = next(Path(args.data).glob(f"{args.volume}_*")) if args.data else None
        if volume_path is not None:
            for size in (256, 512):
                res[f"samples {size}"] = samples_on_rays(volume_path, res["camera"], size)
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
    report(args, res, load_before, os.getloadavg())


#: In the page: what changes while the page works on its view (frames drawn, attribution passes).
ACTIVITY_JS = """() => [document.getElementById('view-canvas').dataset.frames,
  document.getElementById('view-canvas').dataset.quality,
  window.intuitfDebug.gl.stats.attributionPasses]"""


def wait_until_rested(page, quiet_s: float = 1.5, limit_s: float = 120.0) -> None:
    """Until the page has drawn no frame and run no attribution pass for ``quiet_s`` and its
    view is at full resolution (or ``limit_s`` passed)."""
    end = time.monotonic() + limit_s
    last, since = None, time.monotonic()
    while time.monotonic() < end:
        now = page.evaluate(ACTIVITY_JS)
        if now != last:
            last, since = now, time.monotonic()
        elif now[1] == "full" and time.monotonic() - since >= quiet_s:
            return
        page.wait_for_timeout(250)


def browser_part(base: str, token: str, args, chromium: str, hist: dict) -> dict:
    from playwright.sync_api import sync_playwright

    out: dict = {}
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=chromium, headless=True,
                               args=CHROMIUM_ARGS + GL_ARGS[args.gl])  # fmt: skip
        page = b.new_page(viewport={"width": 1440, "height": 900})
        page.set_default_timeout(120_000)
        page.goto(f"{base}/?token={token}")
        page.wait_for_selector("body.ready")
        out["gpu"] = page.evaluate("window.intuitfDebug.gl.renderer()?.gpu || 'no WebGL2'")
        # The page first previews another volume: let it finish (its frame and attribution).
        page.wait_for_function("() => window.intuitfDebug.gl.stats.prepared !== undefined")
        # First picture after choosing the volume (the page's own clock, from the choice).
        # Long main-thread tasks meanwhile show whether loading froze the page.
        page.evaluate(
            "() => { window.__long = []; new PerformanceObserver(l => l.getEntries()"
            ".forEach(e => window.__long.push(e.duration))).observe({entryTypes: ['longtask']}); }"
        )
        t = time.perf_counter()
        page.select_option("#volume-select", args.volume)
        page.wait_for_function(
            "id => window.intuitfDebug.gl.stats.firstPicture[id] !== undefined", arg=args.volume
        )
        out["first picture wall"] = (time.perf_counter() - t) * 1000.0
        stats = page.evaluate("window.intuitfDebug.gl.stats")
        out["long tasks"] = page.evaluate("window.__long")
        out["first picture"] = stats["firstPicture"][args.volume]
        page.wait_for_function(
            "id => window.intuitfDebug.gl.stats.firstFull[id] !== undefined", arg=args.volume
        )
        out["first full"] = page.evaluate(
            f"window.intuitfDebug.gl.stats.firstFull[{args.volume!r}]"
        )
        out["load"] = stats["loadMs"][args.volume]
        out["tf"] = page.evaluate("import('/static/state.js').then(S => S.shownTF())")
        # The view a person gets: the volume's own (upright, chosen for it), once it arrived.
        view = page.evaluate(
            "id => fetch(`/api/volumes/${id}/camera`).then(r => r.json())", args.volume
        )["camera"]
        page.wait_for_function(
            "a => Math.abs(window.intuitfDebug.state.camera.azimuth - a) < 0.01",
            arg=view["azimuth"],
        )
        # Frames are measured once the page rests: its own follow-up work on the new view (the
        # full-resolution frame, the attribution pass in bands, the features strip) would
        # otherwise queue ahead of the first measured frames and be counted in them.
        wait_until_rested(page)
        out["camera"] = page.evaluate("window.intuitfDebug.state.camera")
        out["view size"] = page.evaluate("Number(document.getElementById('view-canvas').width)")
        for size in (256, 512):
            for shading in (True, False):
                key = f"page {size} {'shaded' if shading else 'unshaded'}"
                out[key] = page.evaluate(
                    FRAMES_JS, {"size": size, "n": args.frames, "shading": shading}
                )
        out["page edit 256"] = page.evaluate(EDIT_JS, {"size": 256, "n": args.frames})
        out["page edit 512"] = page.evaluate(EDIT_JS, {"size": 512, "n": args.frames})
        for size in (256, 512):
            for shading in (True, False):
                out[f"dense {size} {'shaded' if shading else 'unshaded'}"] = page.evaluate(
                    DENSE_JS, {"size": size, "shading": shading, "camera": out["camera"]}
                )
        # A real drag of the view: the frames the page drew, and their sides.
        box = page.locator("#view-canvas").bounding_box()
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        page.evaluate("window.__drag = []")
        page.evaluate(
            "() => { const c = document.getElementById('view-canvas');"
            " new MutationObserver(() => { const s = window.intuitfDebug.gl.stats.last;"
            " if (s) window.__drag.push(s); }).observe(c, {attributes: true,"
            " attributeFilter: ['data-frames']}); }"
        )
        page.mouse.move(cx, cy)
        page.mouse.down()
        for i in range(args.frames * 2):
            page.mouse.move(cx + 8 * (i + 1), cy + 2 * (i + 1))
            page.wait_for_timeout(40)
        if args.shots:
            Path(args.shots).mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(Path(args.shots) / f"{args.volume}_drag.png"))
        page.evaluate("window.intuitfDebug.gl.stats.prepared = undefined")
        page.mouse.up()
        page.wait_for_timeout(300)
        drags = page.evaluate("window.__drag")
        out["drag frames"] = [d for d in drags if d["quality"] == "drag"]
        out["drag note"] = page.inner_text("#view-note")
        page.wait_for_function(
            "() => document.getElementById('view-canvas').dataset.quality === 'full'"
        )
        # Click → outline on the view's own picture (the page picks: attribution on the GPU).
        # The page runs the attribution pass once the view rests; a click after that finds it.
        page.wait_for_function("() => window.intuitfDebug.gl.stats.prepared !== undefined")
        out["attribution"] = page.evaluate("window.intuitfDebug.gl.stats.prepared.ms")
        page.evaluate("window.intuitfDebug.gl.stats.clickToOutlineMs = undefined")
        t = time.perf_counter()
        page.mouse.click(cx, cy)
        page.wait_for_function(
            "() => window.intuitfDebug.gl.stats.clickToOutlineMs !== undefined"
            " || document.getElementById('pick-info').textContent.startsWith('Nothing')"
        )
        out["click wall"] = (time.perf_counter() - t) * 1000.0
        out["click"] = page.evaluate("window.intuitfDebug.gl.stats.clickToOutlineMs ?? null")
        out["pick info"] = page.inner_text("#pick-info")
        if args.shots:
            page.screenshot(path=str(Path(args.shots) / f"{args.volume}_pick.png"))
        b.close()
    return out


def report(args, res: dict, load_before, load_after) -> None:
    def row(label: str, values, target=None, unit="ms") -> None:
        if not isinstance(values, list):
            values = [values]
        values = [v for v in values if v is not None]
        if not values:
            print(f"| {label} | – | – | {target or ''} |")
            return
        med = statistics.median(values)
        p90 = pct(values, 0.9)
        mark = "" if target is None else (" ✓" if med <= target else " ✗")
        tgt = "" if target is None else f"≤ {target} {unit}"
        print(f"| {label} | {med:.0f} | {p90:.0f} | {tgt}{mark} |")

    print(
        f"volume {args.volume}; the page's view {res['view size']}²; WebGL2 renderer: {res['gpu']}"
    )
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} "
          f"(on {os.cpu_count()} cores; figures from a loaded machine are upper bounds)")  # fmt: skip
    print()
    print("| measurement | median ms | p90 ms | target |")
    print("|---|---|---|---|")
    row("first picture after choosing the volume", res["first picture wall"], 3000)
    row("  of which in the page: texture fetched, blocks, uploaded, drawn", res["first picture"])
    row("first full-resolution picture (page clock; software draws a half-size one first)",
        res["first full"])  # fmt: skip
    row("  of which texture fetched, block ranges computed, uploaded", res["load"])
    for size, target in ((256, 200), (512, 600)):
        row(f"page frame {size}² shaded, camera turning (drag)", res[f"page {size} shaded"], target)
        row(f"page frame {size}² unshaded", res[f"page {size} unshaded"])
        row(
            f"page frame {size}² after a hand edit (LUT + blocks + frame)", res[f"page edit {size}"]
        )
    sides = sorted({d["width"] for d in res["drag frames"]})
    row(f"page drag frames of a real mouse drag (sides {sides})",
        [d["ms"] for d in res["drag frames"]], 200)  # fmt: skip
    row("click → outline (page clock), attribution ready", res["click"], 300)
    row("  the attribution pass, run once the view rests", res["attribution"])
    row("server still 256² shaded (render_ms)", res["server 256"])
    row("server still 512² shaded (render_ms)", res["server 512"], 500)
    print()
    longs = sorted(res["long tasks"], reverse=True)
    print(f"main-thread tasks over 50 ms from choosing the volume to its first picture: "
          f"{len(longs)}, longest {', '.join(f'{v:.0f}' for v in longs[:3]) or '–'} ms "
          f"(the first draw is one of them)")  # fmt: skip
    if res["drag note"]:
        print(f"on screen while dragging: {res['drag note']!r}")
    print(f"pick: {res['pick info']!r}")
    if "samples 256" in res:
        print()
        print("shader cost per sample (every sample visible, no early end):")
        for size in (256, 512):
            n = res[f"samples {size}"]
            for shading in ("shaded", "unshaded"):
                ms = res[f"dense {size} {shading}"]
                print(f"  {size}² {shading}: {n / 1e6:.1f} M samples in {ms:.0f} ms = "
                      f"{ms * 1e6 / n:.1f} ns a sample ({n / ms / 1e3:.0f} M samples/s)")  # fmt: skip


if __name__ == "__main__":
    main()
