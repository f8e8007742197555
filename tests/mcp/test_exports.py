"""Exports of a volume's current TF through the tool: every format is written under the output
folder in the data's own units, and the files are what the other tools read."""

from __future__ import annotations

import asyncio
import json
import runpy

import pytest
from mcp_util import call, make_config

from mcp import Client


def test_every_format_of_the_current_tf(folders):
    from intuitf.mcp import build_server
    from intuitf.tf import GaussianTF

    server, _ = build_server(make_config(folders))
    tf = {"gaussians": [{"mean": 0.55, "width": 0.04, "height": 0.6, "color": [1, 0.9, 0.7]},
                        {"mean": 0.2, "width": 0.05, "height": 0.05, "color": [0.8, 0.3, 0.3]}]}  # fmt: skip

    async def main():
        async with Client(server) as client:
            opened = await call(client, "open_volume", path=folders["foot"].name)
            vid = opened["id"]
            await call(client, "set_tf", volume=vid, tf=tf)
            out = {}
            for fmt in ("paraview", "slicer", "vtk", "1dt", "json", "png"):
                out[fmt] = await call(client, "export", volume=vid, format=fmt,
                                      path=f"current/{fmt}", size=48)  # fmt: skip
            return out, opened["value_range"]

    out, value_range = asyncio.run(main())
    paths = {k: v["path"] for k, v in out.items()}
    assert paths["paraview"].endswith(".paraview.json") and paths["slicer"].endswith(".vp")
    assert paths["vtk"].endswith(".vtk.py") and paths["1dt"].endswith(".1dt")
    assert out["1dt"]["format"] == "imagevis3d"
    for p in paths.values():
        assert str(folders["out"].resolve()) in p
    lo, hi = out["json"]["value_range"]
    assert [lo, hi] == value_range and hi > 200  # the data's own units
    back = GaussianTF.from_json(open(paths["json"]).read())
    assert [g.mean for g in back.gaussians] == pytest.approx([0.55, 0.2])
    preset = json.loads(open(paths["paraview"]).read())[0]
    xs = preset["Points"][0::4]
    peak = xs[max(range(len(xs)), key=lambda i: preset["Points"][4 * i + 1])]
    assert peak == pytest.approx(lo + 0.55 * (hi - lo), abs=2.0)  # in data units
    lines = open(paths["slicer"]).read().splitlines()
    assert len(lines) == 9 and lines[0] == "1"
    try:
        import vtkmodules.vtkRenderingCore  # noqa: F401
    except ImportError:
        return
    snippet = runpy.run_path(paths["vtk"])
    otf = snippet["opacity_tf"]
    assert otf.GetValue(lo + 0.55 * (hi - lo)) == pytest.approx(0.6, abs=0.01)
