"""The page's empty-space skipping: jumps over empty blocks never skip a visible sample.

The page marks each block of its skipping grid with a jump distance (gl_volume.visibleBlocks):
a ray at a block with distance r leaves the whole cube of blocks within r - 1 at once. A
distance that is too large would skip visible samples; these tests check the distances
against the exact ones, and that the picture does not depend on the grid at all.
"""

from __future__ import annotations

import base64

import numpy as np
import pytest

from helpers.browser import open_app, skip_reason, start_server_with, stop_server
from helpers.data import DATA, data_dir

pytestmark = pytest.mark.slow

BONSAI = "bonsai_256x256x256_uint8.raw.gz"

#: Runs in the page: random block ranges, a LUT visible on one value band; every jump
#: distance against the exact chessboard distance to the nearest visible block.
DISTANCES = """() => import('/static/gl_volume.js').then(V => {
  let seed = 7;
  const rand = () => (seed = (seed * 16807) % 2147483647) / 2147483647;
  const out = [];
  for (const [nb, share] of [[[37, 23, 41], 0.004], [[20, 31, 17], 0.03], [[64, 8, 9], 0.0]]) {
    const n = nb[0] * nb[1] * nb[2];
    const min = new Float32Array(n), max = new Float32Array(n);
    for (let i = 0; i < n; i++) {
      const v = rand() < share ? 0.42 : 0.1;
      min[i] = v;
      max[i] = v + 0.01;
    }
    const occ = new Int32Array(257);
    for (let k = 0; k < 256; k++) occ[k + 1] = occ[k] + (k >= 100 && k <= 120 ? 1 : 0);
    const r = V.visibleBlocks({ nb, size: 2, min, max }, occ);
    const at = (i) => [i % nb[0], Math.floor(i / nb[0]) % nb[1], Math.floor(i / (nb[0] * nb[1]))];
    const vis = [];
    for (let i = 0; i < n; i++) if (min[i] > 0.2) vis.push(at(i));
    let tooFar = 0, wrongVisible = 0, jumps = 0;
    for (let i = 0; i < n; i++) {
      const [x, y, z] = at(i);
      let exact = 255;
      for (const q of vis) exact = Math.min(exact, Math.max(Math.abs(x - q[0]), Math.abs(y - q[1]), Math.abs(z - q[2])));
      if ((r[i] === 0) !== (exact === 0)) wrongVisible++;
      if (r[i] > exact) tooFar++;
      if (r[i] > 1) jumps++;
    }
    out.push({ blocks: n, visible: vis.length, tooFar, wrongVisible, jumps });
  }
  return out;
})"""

#: Runs in the page: the bonsai drawn with skipping grids of several block sizes.
BY_GRID = """async ({id, tf, camera, size, grids}) => {
  const R = await import('/static/gl_renderer.js');
  const V = await import('/static/gl_volume.js');
  const vol = await V.fetchVolume(id, { maxBytes: 64 * 1024 * 1024, maxSide: 2048 });
  const out = {};
  for (const g of grids) {
    const r = new R.GLVolumeRenderer();
    await r.setVolume(vol, await V.blockRanges(vol, g));
    await r.gradientReady;
    r.render({tf, camera, width: size, height: size, shading: true});
    const a = r.readRGB();
    let s = '';
    for (let i = 0; i < a.length; i += 32768) s += String.fromCharCode.apply(null, a.subarray(i, i + 32768));
    out[g] = btoa(s);
  }
  return out;
}"""


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    from playwright.sync_api import sync_playwright

    reason = skip_reason()
    if reason:
        pytest.skip(reason)
    srv = start_server_with(tmp_path_factory.mktemp("skipping"), [BONSAI])
    with sync_playwright() as pw:
        b, pg = open_app(pw.chromium, srv.url, 800, 600)
        yield pg
        b.close()
    stop_server(srv)


def test_jump_distances_never_reach_a_visible_block(page):
    cases = page.evaluate(DISTANCES)
    for case in cases:
        assert case["tooFar"] == 0, case
        assert case["wrongVisible"] == 0, case
    assert cases[0]["jumps"] > 0  # sparse visible blocks: rays jump over empty cubes
    assert cases[2]["visible"] == 0 and cases[2]["jumps"] > 0  # nothing visible at all


def test_the_picture_does_not_depend_on_the_skipping_grid(page):
    if data_dir() is None:
        pytest.skip(f"the real volumes are not in {DATA} (set INTUITF_DATA)")
    tf = {
        "gaussians": [
            {"mean": 0.16, "width": 0.02, "height": 0.08, "color": [0.3, 0.8, 0.3]},
            {"mean": 0.53, "width": 0.03, "height": 0.4, "color": [0.9, 0.6, 0.25]},
        ]
    }
    camera = {"azimuth": 30, "elevation": 20, "zoom": 1.1, "pan": [0.0, 0.0]}
    got = page.evaluate(
        BY_GRID, {"id": "bonsai", "tf": tf, "camera": camera, "size": 96, "grids": [2, 8, 16]}
    )
    assert not page.errors, page.errors
    imgs = {
        g: np.frombuffer(base64.b64decode(b), dtype=np.uint8).reshape(96, 96, 3).astype(int)
        for g, b in got.items()
    }
    assert imgs["2"].max() > 40  # the view shows the tree
    for g in ("8", "16"):
        assert np.abs(imgs[g] - imgs["2"]).max() <= 1, g
