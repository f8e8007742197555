"""The volume view rendered by the page (WebGL2, in headless Chromium's software rasteriser):
frames while dragging, the pick and its outline, the features strip, and the fallbacks that
say so (no WebGL2: the server's frames; a volume over the page's limits: downsampled)."""

from __future__ import annotations

import pytest

from helpers.browser import open_app, show_run, skip_reason, start_server_with, stop_server
from helpers.data import DATA, data_dir

pytestmark = pytest.mark.slow

NEGHIP = "neghip_64x64x64_uint8.raw.gz"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    reason = skip_reason()
    if reason:
        pytest.skip(reason)
    srv = start_server_with(tmp_path_factory.mktemp("glview"), [NEGHIP])
    yield srv
    stop_server(srv)


@pytest.fixture(scope="module")
def chromium():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        yield pw.chromium


def open_page(chromium, server, extra_args=()):
    b, page = open_app(chromium, server.url, extra_args=extra_args, timeout_ms=90_000)
    return b, page, page.errors


def wait_page_frame(page, quality="full", after=0):
    page.wait_for_function(
        "([q, n]) => { const c = document.getElementById('view-canvas');"
        " return c.dataset.renderer === 'webgl2' && c.dataset.quality === q"
        " && Number(c.dataset.frames || 0) > n; }",
        arg=[quality, after],
    )
    return int(page.get_attribute("#view-canvas", "data-frames"))


def test_the_page_renders_drags_picks_and_draws_the_features(chromium, server):
    b, page, errors = open_page(chromium, server)
    try:
        n = wait_page_frame(page)
        assert "WebGL2" in page.inner_text("#view-stats")
        # The picture is the phantom, not an empty canvas.
        lit = page.evaluate(
            "() => { const c = document.getElementById('view-canvas');"
            " const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
            " let k = 0; for (let i = 0; i < d.length; i += 4) if (d[i] + d[i+1] + d[i+2] > 60) k++;"
            " return k / (c.width * c.height); }"
        )
        assert lit > 0.05
        # A drag turns the camera with frames drawn by the page; the release brings a full one.
        box = page.locator("#view-canvas").bounding_box()
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        # The preview's view is the volume's own (asked of the server): wait for it, then drag.
        view = page.evaluate("() => fetch('/api/volumes/phantom/camera').then(r => r.json())")
        page.wait_for_function(
            "a => Math.abs(window.intuitfDebug.state.camera.azimuth - a) < 0.01",
            arg=view["camera"]["azimuth"],
        )
        before = page.evaluate("window.intuitfDebug.state.camera.azimuth")
        page.mouse.move(cx, cy)
        page.mouse.down()
        for k in range(1, 8):
            page.mouse.move(cx + 10 * k, cy + 3 * k)
            page.wait_for_timeout(30)
        wait_page_frame(page, "drag", n)
        page.mouse.up()
        n = wait_page_frame(page, "full", n)
        assert abs(page.evaluate("window.intuitfDebug.state.camera.azimuth") - before) > 5
        # The features strip is drawn by the page (pictures made here, not fetched).
        page.wait_for_selector("#features-strip .feature img")
        srcs = page.eval_on_selector_all(
            "#features-strip .feature img", "ims => ims.map(i => i.src)"
        )
        assert srcs and all(s.startswith("data:image/png") for s in srcs)
        # A click picks by the smallest-area rule from the page's attribution pass and outlines it.
        page.wait_for_function("() => window.intuitfDebug.gl.stats.prepared !== undefined")
        page.mouse.click(cx, cy)
        page.wait_for_function("() => document.getElementById('pick-info').textContent !== ''")
        if page.inner_text("#pick-info").startswith("Selected feature"):
            page.wait_for_function(
                "() => Number(document.getElementById('mask-canvas').dataset.pixels || 0) > 0"
            )
            sel = page.evaluate("[...window.intuitfDebug.state.selected]")
            assert page.get_attribute("#mask-canvas", "data-index") == ",".join(map(str, sel))
            assert page.evaluate("window.intuitfDebug.gl.stats.clickToOutlineMs") is not None
        # A hand edit redraws at once: a lower height changes the picture.
        before = page.evaluate("window.intuitfDebug.gl.stats.frames")
        page.evaluate(
            "import('/static/state.js').then(S => { const tf = JSON.parse(JSON.stringify(S.shownTF()));"
            " tf.gaussians.forEach(g => g.height *= 0.2); S.set({draft: tf}); })"
        )
        page.wait_for_function("n => window.intuitfDebug.gl.stats.frames > n", arg=before)
        assert not errors, errors
    finally:
        b.close()


def test_without_webgl2_the_server_renders_the_view_and_says_why(chromium, server):
    b, page, errors = open_page(chromium, server, ["--disable-webgl", "--disable-webgl2"])
    try:
        page.wait_for_function(
            "() => { const c = document.getElementById('view-canvas');"
            " return c.dataset.quality === 'full' && Number(c.dataset.frames || 0) > 0; }"
        )
        assert page.get_attribute("#view-canvas", "data-renderer") == "server"
        assert "WebGL2" in page.inner_text("#view-note")
        assert "server" in page.inner_text("#view-note")
        assert not errors, errors
    finally:
        b.close()


def test_without_webgl2_a_double_click_asks_the_server_for_one_whole_pick(chromium, server):
    """A double-click is two clicks and a double-click: on the server's path it must cost one
    pick, the whole one, not two single picks computed ahead of it; a click alone still picks."""
    b, page, errors = open_page(chromium, server, ["--disable-webgl", "--disable-webgl2"])
    picks: list[dict] = []
    page.on(
        "request",
        lambda r: picks.append(r.post_data_json) if r.url.endswith("/pick") else None,
    )
    try:
        page.wait_for_function(
            "() => { const c = document.getElementById('view-canvas');"
            " return c.dataset.quality === 'full' && Number(c.dataset.frames || 0) > 0; }"
        )
        box = page.locator("#view-canvas").bounding_box()
        at = (box["x"] + 0.5 * box["width"], box["y"] + 0.5 * box["height"])
        page.mouse.dblclick(*at)
        page.wait_for_function("() => document.getElementById('pick-info').textContent !== ''")
        page.wait_for_timeout(600)  # longer than a single click's wait for a second one
        assert [p["whole"] for p in picks] == [True]
        page.evaluate("document.getElementById('pick-info').textContent = ''")
        page.mouse.click(*at)
        page.wait_for_function("() => document.getElementById('pick-info').textContent !== ''")
        assert [p["whole"] for p in picks] == [True, False]
        assert not errors, errors
    finally:
        b.close()


def test_a_volume_over_the_page_limits_is_downsampled_with_a_note(chromium, server):
    if data_dir() is None or not (DATA / NEGHIP).exists():
        pytest.skip(f"{NEGHIP} is not in {DATA}")
    b, page, errors = open_page(chromium, server)
    try:
        wait_page_frame(page)
        # A page whose memory allows 100 kB of texture: the 64³ volume comes at every 2nd voxel.
        page.evaluate(
            "() => { window.intuitfDebug.gl.renderer().limits = () => ({maxBytes: 100000, maxSide: 2048}); }"
        )
        page.select_option("#volume-select", "neghip")
        page.wait_for_function(
            "() => window.intuitfDebug.gl.stats.firstPicture.neghip !== undefined"
        )
        note = page.inner_text("#view-note")
        assert "Downsampled 2×" in note and "32×32×32" in note and "64×64×64" in note
        assert not errors, errors
    finally:
        b.close()


def _until_quiet(page, seconds: float = 1.5) -> None:
    """Wait until the view has drawn no frame for ``seconds``."""
    seen = None
    for _ in range(40):
        now = page.get_attribute("#view-canvas", "data-frames")
        if seen is not None and now == seen:
            return
        seen = now
        page.wait_for_timeout(seconds * 1000)
    raise AssertionError("the view kept drawing frames")


def _lit_aspect(page) -> float:
    """Height over width of the lit pixels' bounding box in the view."""
    h, w = page.evaluate(
        "() => { const c = document.getElementById('view-canvas');"
        " const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
        " let x0 = 1e9, x1 = -1, y0 = 1e9, y1 = -1;"
        " for (let y = 0; y < c.height; y++) for (let x = 0; x < c.width; x++) {"
        "   const i = 4 * (y * c.width + x);"
        "   if (d[i] + d[i + 1] + d[i + 2] > 90) { x0 = Math.min(x0, x); x1 = Math.max(x1, x);"
        "     y0 = Math.min(y0, y); y1 = Math.max(y1, y); } }"
        " return [y1 - y0 + 1, x1 - x0 + 1]; }"
    )
    return h / max(w, 1)


def test_a_run_made_before_its_volume_got_another_voxel_size_is_drawn_as_judged(
    chromium, server, shots
):
    """The page's copy of a volume has the voxel size the volume has now; a run keeps the one
    it was made with. Drawn with the new one, the run's results showed stretched beside the
    pictures that were judged: the server draws such a run's view, and the view says why."""
    import numpy as np

    zz, yy, xx = np.mgrid[:24, :32, :32]
    ball = np.where(np.hypot(np.hypot(zz - 12, yy - 16), xx - 16) < 9, 200, 20).astype(np.uint8)
    ball.tofile(server.runs.parent / "data" / "ball_32x32x24_uint8.raw")
    vid = next(v["id"] for v in server.api("GET", "/api/volumes") if v["id"].startswith("ball"))
    spec = {
        "volume": vid,
        "intent": {"kind": "text", "text": "a red ball"},
        "judge": {"spec": "metric"},
        "settings": {"population": 4, "generations": 1, "image_size": 48},
    }
    run = server.api("POST", "/api/runs", spec)["name"]
    server.wait_run(run)
    assert server.api("GET", f"/api/runs/{run}")["spacing"] == [1.0, 1.0, 1.0]
    b, page, errors = open_page(chromium, server)
    try:
        show_run(page, run)
        wait_page_frame(page)  # same voxels: the page draws it
        assert "voxels" not in page.inner_text("#view-note")
        server.api("PATCH", f"/api/volumes/{vid}", {"spacing": [1, 1, 2.5]})
        page.reload()
        page.wait_for_selector("body.ready")
        show_run(page, run)
        page.wait_for_function(
            "() => { const c = document.getElementById('view-canvas');"
            " return c.dataset.renderer === 'server' && c.dataset.quality === 'full'; }"
        )
        note = page.inner_text("#view-note")
        assert "made with voxels of 1 × 1 × 1" in note and "server draws its view" in note
        page.screenshot(path=str(shots / "run-with-older-voxels.png"))
        _until_quiet(page)
        assert 0.85 < _lit_aspect(page) < 1.15  # the ball round, as judged (1.26 stretched)
        # A hand edit of the result: drawn on the run's volume too, not stretched 2.5 times.
        n = int(page.get_attribute("#view-canvas", "data-frames"))
        page.evaluate(
            "import('/static/state.js').then(S => { const tf = JSON.parse(JSON.stringify(S.shownTF()));"
            " tf.gaussians.forEach(g => g.height *= 0.9); S.set({draft: tf}); })"
        )
        page.wait_for_function(
            "n => { const c = document.getElementById('view-canvas');"
            " return Number(c.dataset.frames) > n && c.dataset.quality === 'full'; }",
            arg=n,
        )
        _until_quiet(page)  # the edit's own frame, not one of the result asked for before it
        assert page.get_attribute("#view-canvas", "data-renderer") == "server"
        assert 0.85 < _lit_aspect(page) < 1.15
        assert not errors, errors
    finally:
        server.api("PATCH", f"/api/volumes/{vid}", {"spacing": None})
        b.close()
