"""The page's empty-space skipping: jumps over empty blocks never skip a visible sample.

The page marks each block of its skipping grid (gl_volume.visibleBlocks) with a jump distance
(a ray leaves the whole cube of empty blocks around it at once) or, in visible fog, a run (a
ray samples a whole cube of visible blocks with no lookup in between). A jump too long would
skip visible samples; these tests check the jumps and the runs against the exact distances,
and that the picture does not depend on the grid at all.
"""

from __future__ import annotations

import base64

import numpy as np
import pytest

from helpers.browser import open_app, skip_reason, start_server_with, stop_server
from helpers.data import DATA, data_dir

pytestmark = pytest.mark.slow

BONSAI = "bonsai_256x256x256_uint8.raw.gz"

#: Runs in the page: random block ranges, a LUT visible on one value band; every jump and
#: every visible run against the exact chessboard distances to the nearest visible block and
#: to the nearest empty one.
DISTANCES = """() => import('/static/gl_volume.js').then(V => {
  let seed = 7;
  const rand = () => (seed = (seed * 16807) % 2147483647) / 2147483647;
  const out = [];
  const cases = [[[37, 23, 41], 0.004], [[20, 31, 17], 0.03], [[64, 8, 9], 0.0], [[30, 20, 25], 0.97]];
  for (const [nb, share] of cases) {
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
    const vis = [], empty = [];
    for (let i = 0; i < n; i++) (min[i] > 0.2 ? vis : empty).push(at(i));
    const nearest = (p, set) => {
      let best = 255;
      for (const q of set) best = Math.min(best, Math.max(Math.abs(p[0] - q[0]), Math.abs(p[1] - q[1]), Math.abs(p[2] - q[2])));
      return best;
    };
    let tooFar = 0, runTooFar = 0, wrongVisible = 0, jumps = 0, runs = 0;
    for (let i = 0; i < n; i++) {
      const p = at(i);
      const isVisible = r[i] < 128;
      const reach = r[i] & 127; // blocks around it, all like it
      if (isVisible !== (min[i] > 0.2)) wrongVisible++;
      if (!isVisible) {
        if (reach > nearest(p, vis) - 1) tooFar++;
        if (reach > 0) jumps++;
      } else if (reach > 0) {
        if (reach > nearest(p, empty) - 1) runTooFar++;
        runs++;
      }
    }
    out.push({ blocks: n, visible: vis.length, tooFar, runTooFar, wrongVisible, jumps, runs });
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


def test_jumps_never_reach_a_visible_block_nor_runs_an_empty_one(page):
    cases = page.evaluate(DISTANCES)
    for case in cases:
        assert case["tooFar"] == 0, case
        assert case["runTooFar"] == 0, case
        assert case["wrongVisible"] == 0, case
    assert cases[0]["jumps"] > 0  # sparse visible blocks: rays jump over empty cubes
    assert cases[2]["visible"] == 0 and cases[2]["jumps"] > 0  # nothing visible at all
    assert cases[0]["runs"] == 0  # few visible blocks: no runs worked out
    assert cases[3]["runs"] > 0  # visible fog: rays run through cubes of visible blocks


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
