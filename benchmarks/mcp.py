"""``intuitf mcp`` on the CT foot: each tool's time, and the size and token cost of each result.

Run: ``python benchmarks/mcp.py`` (options: ``--data DIR`` (default ``$INTUITF_DATA`` or
``../shared/data/volumes``), ``--max-dim N`` (the foot is 256³; default 128), ``--transport
memory|stdio``, ``--quick`` (64³, a tiny run), ``--json PATH`` to keep the figures).

An agent session is played through the SDK's own client, against a server built as
``intuitf mcp`` builds it (in memory, or as a subprocess over stdio): open and describe the
foot, render it at several sizes and in both camera forms, edit its TF, start a text run judged
by the fake OpenAI-compatible model server (``intuitf.testing``; 50 ms a verdict), follow it,
read the gallery, give and undo a verdict, show the features, select one at a pixel, refine
it, branch, ask anew, and export to every format.

For every call: the wall time the client saw; the bytes of the whole result as JSON on the
wire (text, structured content and base64 images together); the picture's format, size and
bytes; and the tokens a Claude model would count for it (image: ``w * h / 750`` after its own
downscaling; text: characters / 4, the text content only, which is what clients show the
model). Limits the results must keep: 1 MiB (desktop clients refuse bigger results) and well
under 25,000 tokens (Claude Code's default limit for one tool result).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This file's name is the SDK's package name: import the SDK, not this script.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

FOOT = "foot_zfp8lossy_256x256x256_uint8.raw.gz"
LIMIT_BYTES = 1024 * 1024
LIMIT_TOKENS = 25_000


def _data_dir(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    if os.environ.get("INTUITF_DATA"):
        return Path(os.environ["INTUITF_DATA"])
    return Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "volumes"


class Recorder:
    """Calls tools and keeps a row of figures per call."""

    def __init__(self, client) -> None:
        self.client = client
        self.rows: list[dict] = []

    async def __call__(self, tool: str, label: str | None = None, **args) -> dict:
        from intuitf.mcp.pictures import image_tokens, text_tokens

        t0 = time.perf_counter()
        res = await self.client.call_tool(tool, args)
        ms = (time.perf_counter() - t0) * 1000
        if res.is_error:
            raise SystemExit(f"{tool} failed: {res.content[0].text}")
        wire = len(res.model_dump_json(by_alias=True, exclude_none=True).encode())
        text = "".join(c.text for c in res.content if c.type == "text")
        images = [c for c in res.content if c.type == "image"]
        row = {
            "tool": label or tool,
            "ms": round(ms, 1),
            "bytes": wire,
            "text_tokens": text_tokens(text),
            "image": None,
            "image_tokens": 0,
        }
        if images:
            info = res.structured_content["image"]
            row["image"] = f"{info['mime_type'].split('/')[1]} {info['width']}x{info['height']}"
            row["image_bytes"] = info["bytes"]
            row["image_tokens"] = image_tokens(info["width"], info["height"])
        row["tokens"] = row["text_tokens"] + row["image_tokens"]
        self.rows.append(row)
        return res.structured_content


async def session(client, data: Path, max_dim: int, model_url: str, quick: bool) -> list[dict]:
    call = Recorder(client)
    await call("list_volumes")
    vol = await call("open_volume", path=str(data / FOOT), max_dim=max_dim)
    vid = vol["id"]
    await call("describe_volume", volume=vid)
    sizes = (128, 256) if quick else (256, 512, 1024)
    for size in sizes:
        await call("render", f"render {size} (first)" if size == sizes[0] else f"render {size}",
                   volume=vid, size=size, camera={"azimuth": 30, "elevation": 20})  # fmt: skip
    shot = await call("render", f"render {sizes[-1]} again", volume=vid, size=sizes[-1],
                      camera={"azimuth": 30, "elevation": 20})  # fmt: skip
    await call("render", f"render {sizes[-1]} jpeg", volume=vid, size=sizes[-1],
               camera={"azimuth": 30, "elevation": 20}, format="jpeg")  # fmt: skip
    await call("render", f"render {sizes[-1]} vtk camera", volume=vid, size=sizes[-1],
               camera=shot["camera"]["vtk"])  # fmt: skip
    tf = (await call("get_tf", volume=vid))["tf"]
    await call("edit_gaussian", volume=vid, index=len(tf["gaussians"]) - 1, height=0.8)
    await call("set_tf", volume=vid, tf=tf)

    settings = {"population": 6 if quick else 12, "generations": 2 if quick else 3,
                "image_size": 64 if quick else 128, "seed": 2}  # fmt: skip
    run = (await call("start_run", volume=vid, intent="the bones in ivory, the skin faint",
                      judge=model_url, settings=settings))["run"]  # fmt: skip
    await call("run_status", run=run)
    while True:
        got = await call("wait_for_generation", run=run, timeout_s=120)
        if not got["live"] and got["status"] != "finishing":
            break
    await call("run_status", "run_status (all events)", run=run, since=0, limit=500)
    await call("run_status", "run_status (+ matches)", run=run, since=0, limit=500, matches=True)
    gal = await call("gallery", run=run, k=4, size=192)
    await call("gallery", "gallery k=8 size 256", run=run, k=8, size=256)
    ids = [c["id"] for c in gal["candidates"]]
    await call("prefer", run=run, better=ids[-1], worse=ids[0])
    await call("undo_verdict", run=run)
    best = ids[0]
    await call("features", candidate=best, size=160)
    pic = await call("render", "render candidate 512", candidate=best, size=512)
    from PIL import Image

    arr = np.asarray(Image.open(pic["path"]))[..., :3].astype(int).sum(axis=2)
    y, x = np.unravel_index(int(np.argmax(arr)), arr.shape)
    await call("select_feature", candidate=best, x=int(x), y=int(y), size=512)
    ref = (await call("refine", candidate=best, text="make it warmer", generations=1,
                      judge="metric"))["run"]  # fmt: skip
    br = (await call("branch", run=run, generation=1, changes={"judge": "metric"}))["run"]
    for r in (ref, br):
        while True:
            got = await call("wait_for_generation", run=r, timeout_s=120)
            if not got["live"] and got["status"] != "finishing":
                break
    await call("new_query", run=br, intent="only the bones, white", generations=1)
    while True:
        got = await call("wait_for_generation", run=br, timeout_s=120)
        if not got["live"] and got["status"] != "finishing":
            break
    for fmt in ("paraview", "slicer", "vtk", "imagevis3d", "json", "png"):
        await call("export", f"export {fmt}", candidate=best, format=fmt, path=f"bench/{fmt}",
                   size=512)  # fmt: skip
    await call("list_runs")
    return call.rows


def _table(rows: list[dict]) -> str:
    out = [f"{'call':28} {'ms':>8} {'result KiB':>10} {'picture':>16} {'tokens':>7}"]
    for r in rows:
        out.append(
            f"{r['tool'][:28]:28} {r['ms']:8.1f} {r['bytes'] / 1024:10.1f} "
            f"{r['image'] or '-':>16} {r['tokens']:7d}"
        )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data")
    ap.add_argument("--max-dim", type=int, default=128)
    ap.add_argument("--transport", choices=("memory", "stdio"), default="memory")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json")
    a = ap.parse_args()
    data = _data_dir(a.data).resolve()
    if not (data / FOOT).exists():
        raise SystemExit(f"{FOOT} not found in {data} (set INTUITF_DATA or --data)")
    max_dim = 64 if a.quick else a.max_dim

    from intuitf.mcp import McpConfig, Roots, build_server
    from intuitf.testing.fake_mllm import FakeMLLMServer
    from mcp import Client, StdioServerParameters

    work = Path(tempfile.mkdtemp(prefix="intuitf-mcp-bench-"))
    roots = Roots(data=[data], runs=work / "runs", out=work / "out")
    for p in (roots.runs, roots.out):
        p.mkdir(parents=True, exist_ok=True)
    score = lambda img: float(np.asarray(img, np.float64).mean())  # noqa: E731
    with FakeMLLMServer(score=score, latency=0.05, seed=1) as srv:
        if a.transport == "memory":
            server, _ = build_server(McpConfig(roots=roots))
            target = server
        else:
            target = StdioServerParameters(
                command=sys.executable,
                args=[
                    "-m",
                    "intuitf",
                    "mcp",
                    "--data",
                    str(data),
                    "--runs",
                    str(roots.runs),
                    "--out",
                    str(roots.out),
                ],  # fmt: skip
            )

        async def run():
            async with Client(target) as client:
                return await session(client, data, max_dim, srv.base_url, a.quick)

        t0 = time.perf_counter()
        rows = asyncio.run(run())
        total = time.perf_counter() - t0
    print(f"intuitf mcp on the foot at {max_dim}³, {a.transport} transport, "
          f"session {total:.1f} s, work folder {work}")  # fmt: skip
    print(_table(rows))
    biggest = max(rows, key=lambda r: r["bytes"])
    most = max(rows, key=lambda r: r["tokens"])
    print(f"largest result: {biggest['tool']} {biggest['bytes'] / 1024:.1f} KiB "
          f"(limit {LIMIT_BYTES // 1024} KiB); most tokens: {most['tool']} {most['tokens']} "
          f"(limit {LIMIT_TOKENS})")  # fmt: skip
    ok = biggest["bytes"] < LIMIT_BYTES and most["tokens"] < LIMIT_TOKENS
    print("every result within the limits" if ok else "A RESULT IS OVER A LIMIT")
    if a.json:
        Path(a.json).write_text(json.dumps({"max_dim": max_dim, "transport": a.transport,
                                            "seconds": total, "rows": rows}, indent=1))  # fmt: skip
    if not ok:
        sys.exit(1)


if __name__ == "__main__":
    main()
