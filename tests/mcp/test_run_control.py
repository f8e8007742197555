"""Run control through the tools: pause and continue a live run, a budget that stops a run and
a continue that raises it (nothing paid for is asked again), cancel, and the server's default
budget for model-judged runs."""

from __future__ import annotations

import asyncio

import pytest
from mcp_util import call, make_config, wait_run_end

from mcp import Client

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]

SETTINGS = {"population": 6, "generations": 2, "image_size": 32, "output_size": 32, "seed": 4}


@pytest.fixture
def slow_model():
    """A model server slow enough (0.3 s a verdict) that a pause lands mid-generation."""
    import numpy as np

    from intuitf.testing.fake_mllm import FakeMLLMServer

    with FakeMLLMServer(score=lambda img: float(np.asarray(img, np.float64).mean()),
                        latency=0.3, seed=5) as srv:  # fmt: skip
        yield srv


def test_pause_continue_budget_and_cancel(folders, slow_model):
    from intuitf.mcp import build_server

    fake_model = slow_model
    # The server's default budget applies to model-judged runs that bring none of their own.
    server, _ = build_server(make_config(folders, budget_calls=5))

    async def main():
        async with Client(server) as client:
            vid = (await call(client, "open_volume", path="phantom", max_dim=32))["id"]
            started = await call(client, "start_run", volume=vid, intent="white bone",
                                 judge=fake_model.base_url, settings=SETTINGS)  # fmt: skip
            run = started["run"]
            # The agent is told how its words were read, as a person is.
            assert started["understood"][0].startswith('"bone": white')
            paused = await call(client, "pause_run", run=run)
            assert paused["paused"] is True
            status = await call(client, "run_status", run=run)
            assert any(e["type"] == "status" and e["data"]["status"] == "paused"
                       for e in status["events"])  # fmt: skip
            # Paused: no generation ends while we wait a little.
            held = await call(client, "wait_for_generation", run=run, timeout_s=1.0)
            assert held["outcome"] == "timeout" and held["live"]
            going = await call(client, "continue_run", run=run)
            assert going == {"run": run, "status": "running", "resumed": False}
            stopped = await wait_run_end(client, run)
            assert stopped["info"]["status"] == "budget"
            calls = stopped["info"]["cost"]["calls"]
            assert 0 < calls <= 5
            asked = fake_model.stats.requests
            more = await call(client, "continue_run", run=run, budget_calls=500)
            assert more["resumed"] is True
            done = await wait_run_end(client, run)
            assert done["info"]["status"] == "completed" and done["info"]["generations_done"] == 2
            # The verdicts already paid for were not asked again.
            new_calls = done["info"]["cost"]["calls"] - calls
            assert fake_model.stats.requests - asked == new_calls

            other = (await call(client, "start_run", volume=vid, intent="white bone",
                                judge="metric", settings={**SETTINGS, "generations": 50}))["run"]  # fmt: skip
            await call(client, "wait_for_generation", run=other, timeout_s=60)
            cancelled = await call(client, "cancel_run", run=other)
            assert cancelled["status"] == "cancelling"
            end = await wait_run_end(client, other)
            assert end["info"]["status"] == "cancelled"
            assert end["info"]["generations_done"] < 50

    asyncio.run(main())


def test_runs_from_a_reference_picture_and_a_sketch(folders):
    """Intents with pictures: a reference the agent rendered, a sketch over a rendering (both
    under the output folder), and a new query with a reference on a finished run."""
    import numpy as np
    from PIL import Image

    from intuitf.mcp import build_server

    server, _ = build_server(make_config(folders))
    small = {**SETTINGS, "population": 4, "generations": 1}

    async def main():
        async with Client(server) as client:
            vid = (await call(client, "open_volume", path=folders["foot"].name))["id"]
            base = (await call(client, "render", volume=vid, size=64))["path"]
            strokes = np.zeros((64, 64, 4), np.uint8)
            strokes[20:40, 20:44] = (230, 40, 30, 255)  # "this part red"
            sketch = folders["out"] / "strokes.png"
            Image.fromarray(strokes, "RGBA").save(sketch)
            by_image = await call(client, "start_run", volume=vid, judge="metric", settings=small,
                                  intent={"kind": "image", "reference": base})  # fmt: skip
            by_sketch = await call(client, "start_run", volume=vid, judge="metric", settings=small,
                                   intent={"sketch": str(sketch), "base": base})  # fmt: skip
            ends = [await wait_run_end(client, r["run"]) for r in (by_image, by_sketch)]
            asked = await call(client, "new_query", run=by_image["run"], generations=1,
                               intent={"kind": "image", "reference": base})  # fmt: skip
            again = await wait_run_end(client, by_image["run"])
            # A branch from a candidate, with other words: the candidate joins its first
            # population and the history links them.
            best = await call(client, "gallery", run=by_sketch["run"], k=1, pictures=False)
            cid = best["candidates"][0]["id"]
            br = await call(client, "branch", run=by_sketch["run"], candidate=cid,
                            changes={"intent": "white bone", "settings": {"generations": 1}})  # fmt: skip
            assert br["candidate"] == cid.split("/")[1]
            done = await wait_run_end(client, br["run"])
            assert done["info"]["parent"]["candidate"] == cid.split("/")[1]
            assert done["info"]["intent"]["kind"] == "text"
            start = await call(client, "get_tf", candidate=f"{br['run']}/g000-000")
            parent_tf = await call(client, "get_tf", candidate=cid)
            assert start["tf"]["gaussians"] == parent_tf["tf"]["gaussians"]
            return ends, asked, again

    ends, asked, again = asyncio.run(main())
    assert [e["info"]["intent"]["kind"] for e in ends] == ["image", "sketch"]
    assert all(e["info"]["status"] == "completed" for e in ends)
    assert asked["applied"] and again["info"]["generations_done"] == 2
    # The run folders hold copies of the pictures: the agent's files may go away.
    run_dir = folders["runs"] / ends[1]["run"]
    assert any(p.suffix == ".png" for p in (run_dir / "intent").iterdir())


def test_a_client_leaving_stops_its_runs_cleanly_and_a_new_server_continues_them(folders):
    from mcp_util import stdio_params

    from intuitf.mcp import build_server
    from intuitf.session.lock import in_use

    long = {**SETTINGS, "population": 4, "generations": 40}

    async def first():
        async with Client(stdio_params(folders)) as client:
            vid = (await call(client, "open_volume", path="phantom", max_dim=32))["id"]
            run = (await call(client, "start_run", volume=vid, intent="white bone",
                              judge="metric", settings=long))["run"]  # fmt: skip
            # A wait does not hold up the other tools: with the run paused, a wait is pending
            # while status and a picture are answered; going on ends the wait.
            await call(client, "pause_run", run=run)
            # A generation whose last match was already judged still ends: let it.
            await call(client, "wait_for_generation", run=run, timeout_s=1.5)
            waiting = asyncio.create_task(
                call(client, "wait_for_generation", run=run, timeout_s=120)
            )
            await call(client, "run_status", run=run)
            await call(client, "render", volume=vid, size=48)
            assert not waiting.done()
            await call(client, "continue_run", run=run)
            got = await waiting
            assert got["outcome"] == "generation_ended" and got["live"]
            return run

    run = asyncio.run(first())  # the client closes the server with the run going
    assert not in_use(folders["runs"] / run)
    server, _ = build_server(make_config(folders))

    async def second():
        async with Client(server) as client:
            status = await call(client, "run_status", run=run)
            assert status["info"]["status"] == "cancelled" and not status["live"]
            done_before = status["info"]["generations_done"]
            assert 1 <= done_before < 40
            going = await call(client, "continue_run", run=run)
            assert going["resumed"] and going["generation"] == done_before
            await call(client, "wait_for_generation", run=run, timeout_s=120)
            await call(client, "cancel_run", run=run)
            return await wait_run_end(client, run), done_before

    end, before = asyncio.run(second())
    assert end["info"]["generations_done"] > before
