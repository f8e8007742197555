"""A whole agent session through the SDK's own client, in memory and over stdio: open the foot,
render it, start a text run judged by the fake model server, follow it, read the gallery, steer
it, select a feature by picture coordinates, refine it, branch, ask anew, and export."""

from __future__ import annotations

import asyncio
import base64
import io
import json

import numpy as np
import pytest
from mcp_util import FOOT_SIZE, call, call_error, make_config, stdio_params, wait_run_end
from PIL import Image

from intuitf.session.views import pick_bar
from mcp import Client

pytestmark = pytest.mark.timeout(600)

SETTINGS = {"population": 6, "generations": 2, "image_size": 48, "output_size": 48, "seed": 1}


def _image(result) -> Image.Image:
    blocks = [c for c in result.content if c.type == "image"]
    assert len(blocks) == 1, "one picture per result"
    return Image.open(io.BytesIO(base64.b64decode(blocks[0].data)))


async def scenario(client: Client, folders, model_url: str) -> dict:
    seen: dict = {}
    # -- volumes -------------------------------------------------------------------------
    listed = await call(client, "list_volumes")
    names = [f["name"] for f in listed["files"]]
    assert "foot" in names
    assert all("secret" not in f["path"] for f in listed["files"])  # the link out is hidden
    foot = await call(client, "open_volume", path=folders["foot"].name)
    vid = foot["id"]
    assert vid == "foot" and foot["shape_xyz"] == [FOOT_SIZE] * 3
    assert foot["value_range"][1] > 200 and foot["materials"]
    again = await call(client, "open_volume", path=str(folders["foot"]))
    assert again["id"] == vid  # the same file and options: the same volume
    desc = await call(client, "describe_volume", volume=vid)
    assert desc["histogram"]["bins"] == 64 and max(desc["histogram"]["log_counts"]) == 1.0

    # -- a picture from both camera forms ----------------------------------------------
    res = await client.call_tool("render", {"volume": vid, "size": 96,
                                            "camera": {"azimuth": 30, "elevation": 20}})  # fmt: skip
    assert not res.is_error, res.content[0].text
    pic = res.structured_content
    img = _image(res)
    assert img.size == (96, 96) and pic["image"]["mime_type"] == "image/png"
    assert (folders["out"] / "pictures").resolve() in __import__("pathlib").Path(
        pic["path"]
    ).parents
    full = np.asarray(Image.open(pic["path"]))[..., :3]
    assert full.shape == (96, 96, 3) and full.max() > 40  # the foot is visible
    vtk_cam = pic["camera"]["vtk"]
    res2 = await client.call_tool("render", {"volume": vid, "size": 96, "camera": vtk_cam})
    again_img = np.asarray(Image.open(res2.structured_content["path"]))[..., :3].astype(int)
    assert np.abs(again_img - full.astype(int)).mean() < 1.0  # the VTK form is the same view

    # -- the current TF -------------------------------------------------------------------
    tf = (await call(client, "get_tf", volume=vid))["tf"]
    edited = await call(client, "edit_gaussian", volume=vid, index=0, height=0.0)
    assert edited["tf"]["gaussians"][0]["height"] == 0.0
    await call(client, "set_tf", volume=vid, tf=tf)

    # -- a run in the background ----------------------------------------------------------
    started = await call(client, "start_run", volume=vid, intent="the bones in ivory",
                         judge=model_url, settings=SETTINGS)  # fmt: skip
    run = started["run"]
    assert started["status"] == "running" and started["plan"]
    assert "key" not in json.dumps(started).lower()
    # The server answers other tools while the run goes.
    status = await call(client, "run_status", run=run)
    assert status["live"] or status["status"] in ("completed", "running")
    waited = await call(client, "wait_for_generation", run=run, timeout_s=120)
    assert waited["outcome"] in ("generation_ended", "run_ended")
    types = [e["type"] for e in waited["events"]]
    assert "generation_ended" in types
    all_events = await call(client, "run_status", run=run, since=0, limit=500, matches=True)
    seqs = [e["seq"] for e in all_events["events"]]
    assert seqs == sorted(seqs) and seqs[0] == 1
    later = await call(client, "run_status", run=run, since=all_events["next_since"])
    assert all(e["seq"] > all_events["next_since"] for e in later["events"])
    brief = await call(client, "run_status", run=run, since=0, limit=500)
    assert brief["events"] and all(e["type"] != "match_judged" for e in brief["events"])
    assert brief["next_since"] >= all_events["next_since"]
    assert any(e["type"] == "match_judged" and e["data"]["reasons"] for e in all_events["events"])
    final = await wait_run_end(client, run)
    assert final["info"]["status"] == "completed" and final["info"]["generations_done"] == 2
    assert final["info"]["cost"]["calls"] > 0  # the fake model judged it

    # -- the gallery ----------------------------------------------------------------------
    res = await client.call_tool("gallery", {"run": run, "k": 3, "size": 64})
    assert not res.is_error, res.content[0].text
    gal = res.structured_content
    assert _image(res).size[0] >= 64
    ids = [c["id"] for c in gal["candidates"]]
    ratings = [c["rating"] for c in gal["candidates"]]
    assert len(ids) == 3 and ratings == sorted(ratings, reverse=True)
    assert all(i.startswith(f"{run}/g") for i in ids)
    assert any(c["judge"] and c["judge"][0]["reasons"] for c in gal["candidates"])

    # -- verdicts: the agent prefers the third to the first ---------------------------------
    v = await call(client, "prefer", run=run, better=ids[2], worse=ids[0], note="crisper")
    assert v["verdict"]["winners"] == [ids[2].split("/")[1]]
    assert v["ranking"].index(ids[2].split("/")[1]) < v["ranking"].index(ids[0].split("/")[1])
    undone = await call(client, "undo_verdict", run=run)
    assert undone["verdict"]["undone"] is True
    chosen = await call(client, "choose_best", run=run, best=ids[1], among=ids)
    assert chosen["ranking"][0] == ids[1].split("/")[1]
    back = await call(client, "undo_verdict", run=run)
    assert back["ranking"][0] == ids[0].split("/")[1]  # undone: the judge's order again

    # -- select a feature where the best candidate shows something -------------------------
    best = ids[0]
    shot = await call(client, "render", candidate=best, size=96)
    arr = np.asarray(Image.open(shot["path"]))[..., :3].astype(int).sum(axis=2)
    y, x = np.unravel_index(int(np.argmax(arr)), arr.shape)
    res = await client.call_tool("select_feature", {"candidate": best, "x": int(x), "y": int(y),
                                                    "size": 96})  # fmt: skip
    assert not res.is_error, res.content[0].text
    sel = res.structured_content
    assert sel["chosen"] is not None and sel["selected"] == [sel["chosen"]]
    visible = sel["visible_here"]
    # The paper's rule among the features that make the pixel (session.views.pick_smallest).
    bar = pick_bar([(f["index"], f["share"], f["area_pixels"]) for f in visible])
    making = [f for f in visible if f["share"] >= bar]
    assert sel["chosen"] == min(making, key=lambda f: (f["area_pixels"], -f["share"]))["index"]
    assert _image(res).size == (2 * 96 + 4, 96)  # the pick and the feature alone
    feats = await call(client, "features", candidate=best, size=48)
    assert len(feats["features"]) == len(
        (await call(client, "get_tf", candidate=best))["tf"]["gaussians"]
    )

    # -- refine the selected feature with words ---------------------------------------------
    ref = await call(client, "refine", candidate=best, text="make it red", generations=1,
                     judge="metric")  # fmt: skip
    assert ref["selected"] == sel["selected"]
    done = await wait_run_end(client, ref["run"])
    assert done["info"]["status"] == "completed"
    refined = (await call(client, "gallery", run=ref["run"], k=1, pictures=False))["candidates"][0]
    before = (await call(client, "get_tf", candidate=best))["tf"]["gaussians"]
    after = (await call(client, "get_tf", candidate=refined["id"]))["tf"]["gaussians"]
    kept = [i for i in range(len(before)) if i not in sel["selected"]]
    for i in kept:  # only the selected feature may change
        for key in ("mean", "width", "height", "color"):
            assert after[i][key] == pytest.approx(before[i][key]), (i, key)

    # -- select the whole of what the pixel shows --------------------------------------------
    res = await client.call_tool("select_feature", {"candidate": best, "x": int(x), "y": int(y),
                                                    "size": 96, "whole": True, "clear": True})  # fmt: skip
    assert not res.is_error, res.content[0].text
    whole = res.structured_content
    assert whole["chosen"] == sel["chosen"]  # the paper's choice is still named
    assert whole["selected"] == sorted(f["index"] for f in making)
    if len(making) > 1:
        assert whole["picked"] == whole["selected"] and len(whole["gaussians"]) == len(making)

    # -- branch and ask anew ----------------------------------------------------------------
    br = await call(client, "branch", run=run, generation=1, changes={"judge": "metric"})
    assert br["run"] != run
    await wait_run_end(client, br["run"])
    q = await call(client, "new_query", run=br["run"], intent="only the bones, white",
                   generations=1)  # fmt: skip
    assert q["applied"] is True
    # How the new words were read, said when they are applied.
    assert q["understood"][0].startswith('"bones": '), q
    await wait_run_end(client, br["run"])
    runs = (await call(client, "list_runs"))["runs"]
    parents = {r["name"]: (r["parent"] or {}).get("run") for r in runs}
    assert parents[br["run"]] == run and parents[ref["run"]] == run

    # -- exports into the output folder -----------------------------------------------------
    out = {}
    for fmt in ("paraview", "slicer", "vtk", "imagevis3d", "json", "png"):
        res = await client.call_tool("export", {"candidate": best, "format": fmt,
                                                "path": f"exports/best-{fmt}", "size": 64})  # fmt: skip
        assert not res.is_error, res.content[0].text
        out[fmt] = res.structured_content
        path = __import__("pathlib").Path(out[fmt]["path"])
        assert path.is_file() and folders["out"].resolve() in path.parents
    preset = json.loads(open(out["paraview"]["path"]).read())[0]
    assert preset["RGBPoints"] and preset["Points"]
    assert max(preset["RGBPoints"][0::4]) <= 255.0 + 1e-6  # the data's own units
    from intuitf.tf import GaussianTF

    exported = GaussianTF.from_json(open(out["json"]["path"]).read())
    assert [g.mean for g in exported.gaussians] == pytest.approx([g["mean"] for g in before])
    assert open(out["imagevis3d"]["path"]).readline().strip() == "4096"
    assert Image.open(out["png"]["path"]).size == (64, 64)
    seen["runs"] = [run, ref["run"], br["run"]]
    return seen


def test_scenario_in_memory(folders, fake_model):
    from intuitf.mcp import build_server

    server, _service = build_server(make_config(folders))

    async def main():
        async with Client(server) as client:
            tools = {t.name for t in (await client.list_tools()).tools}
            assert {"render", "start_run", "gallery", "select_feature", "refine",
                    "export"} <= tools  # fmt: skip
            return await scenario(client, folders, fake_model.base_url)

    seen = asyncio.run(main())
    assert len(seen["runs"]) == 3


@pytest.mark.slow
def test_scenario_over_stdio(folders, fake_model):
    async def main():
        async with Client(stdio_params(folders)) as client:
            return await scenario(client, folders, fake_model.base_url)

    seen = asyncio.run(main())
    # Each run's folder is released once the client closes the server.
    from intuitf.session.lock import in_use

    assert not any(in_use(folders["runs"] / r) for r in seen["runs"])


def test_call_error_helper_sees_tool_errors(folders):
    from intuitf.mcp import build_server

    server, _ = build_server(make_config(folders))

    async def main():
        async with Client(server) as client:
            return await call_error(client, "describe_volume", volume="nope")

    assert "open_volume" in asyncio.run(main())
