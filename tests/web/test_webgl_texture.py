"""``GET /api/volumes/{id}/texture``: the page's copy of a volume, its layout and its caching."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from helpers.web_backend import AUTH, make_app
from intuitf.volume import Volume
from intuitf.web.routes_texture import choose_step, encode_texture, texture_format


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(make_app(tmp_path_factory.mktemp("runs")), headers=AUTH) as c:
        yield c


def test_r8_texture_holds_the_original_bytes_and_maps_them_to_normalised_values(client):
    r = client.get("/api/volumes/phantom/texture")
    assert r.status_code == 200, r.text
    h = r.headers
    assert h["x-volume-format"] == "r8" and h["x-volume-step"] == "1"
    nx, ny, nz = (int(v) for v in h["x-volume-dims"].split(","))
    assert len(r.content) == nx * ny * nz
    # The map brings the bytes to the normalised values the server's renderer classifies.
    from intuitf.volume import load_volume

    vol = load_volume("builtin:phantom")
    scale, offset = (float(v) for v in h["x-volume-map"].split(","))
    raw = np.frombuffer(r.content, dtype=np.uint8).reshape(nz, ny, nx)
    assert np.allclose(raw / 255.0 * scale + offset, vol.data, atol=1e-6)
    assert int(h["x-volume-lut-size"]) == vol.lut_size == 256


def test_the_browser_revalidates_and_gets_304(client):
    r = client.get("/api/volumes/phantom/texture")
    assert r.headers["cache-control"] == "private, no-cache"
    etag = r.headers["etag"]
    again = client.get("/api/volumes/phantom/texture", headers={"If-None-Match": etag})
    assert again.status_code == 304 and again.content == b""
    other = client.get("/api/volumes/phantom/texture?max_bytes=200000")
    assert other.headers["etag"] != etag  # another size is another copy


def test_a_volume_over_the_page_limits_is_downsampled_and_says_so(client):
    r = client.get("/api/volumes/phantom/texture?max_bytes=120000&max_side=2048")
    h = r.headers
    step = int(h["x-volume-step"])
    dims = [int(v) for v in h["x-volume-dims"].split(",")]
    full = [int(v) for v in h["x-volume-full-dims"].split(",")]
    assert step == 2 and dims == [-(-n // 2) for n in full]
    assert len(r.content) == dims[0] * dims[1] * dims[2] <= 120000
    assert [float(v) for v in h["x-volume-spacing"].split(",")] == [2.0, 2.0, 2.0]


def test_unknown_volume_is_a_404(client):
    r = client.get("/api/volumes/nope/texture")
    assert r.status_code == 404 and "volume" in r.json()["detail"]


def test_wide_data_goes_as_half_floats_of_the_normalised_value():
    rng = np.random.default_rng(1)
    a = rng.integers(0, 3000, size=(5, 6, 7)).astype(np.uint16)
    vol = Volume.from_array(a, name="ct", spacing=(1.0, 1.0, 2.0))
    assert texture_format(vol) == "r16f"
    body, h = encode_texture(vol, "r16f", 1)
    half = np.frombuffer(body, dtype="<f2").reshape(5, 6, 7)
    # A half float resolves a normalised value to 1/2048 or better.
    assert np.abs(half.astype(np.float32) - vol.data).max() <= 1 / 2048
    assert h["X-Volume-Dims"] == "7,6,5" and h["X-Volume-Spacing"] == "1.0,1.0,2.0"


def test_step_is_the_smallest_that_fits():
    assert choose_step((256, 256, 256), 1, 1 << 30, 2048) == 1
    assert choose_step((512, 512, 600), 2, 256 << 20, 2048) == 2
    assert choose_step((4096, 64, 64), 1, 1 << 30, 2048) == 2
