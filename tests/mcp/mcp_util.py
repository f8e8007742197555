"""Shared steps of the MCP tests: a server's config, its stdio command, calling a tool and
checking its result, waiting for a run to end."""

from __future__ import annotations

import os
import sys
from typing import Any

FOOT_SIZE = 48


def make_config(folders, **kw):
    from intuitf.mcp import McpConfig, Roots

    roots = Roots(data=[folders["data"]], runs=folders["runs"], out=folders["out"])
    folders["runs"].mkdir(exist_ok=True)
    folders["out"].mkdir(exist_ok=True)
    return McpConfig(roots=roots, device="cpu", **kw)


def stdio_params(folders, *extra: str):
    """How a client starts ``intuitf mcp`` as a subprocess over stdio."""
    from mcp import StdioServerParameters

    args = ["-m", "intuitf", "mcp", "--data", str(folders["data"]), "--runs",
            str(folders["runs"]), "--out", str(folders["out"]), "--device", "cpu", *extra]  # fmt: skip
    env = {
        k: v
        for k, v in os.environ.items()
        if k in ("PATH", "HOME", "INTUITF_DATA", "NUMBA_CACHE_DIR")
    }
    return StdioServerParameters(command=sys.executable, args=args, env=env)


async def call(client, tool: str, **args: Any) -> dict:
    """Call ``tool``; its structured result (fails the test on a tool error)."""
    res = await client.call_tool(tool, args)
    assert not res.is_error, f"{tool}: {res.content[0].text}"
    assert res.structured_content is not None, tool
    return res.structured_content


async def call_error(client, tool: str, **args: Any) -> str:
    """Call ``tool`` expecting a tool error; its message."""
    res = await client.call_tool(tool, args)
    assert res.is_error, f"{tool} {args} should fail but gave {res.content[0].text[:300]}"
    text = res.content[0].text
    assert "Traceback" not in text
    return text


async def wait_run_end(client, run: str, rounds: int = 40) -> dict:
    """Wait (through wait_for_generation) until ``run`` is no longer live; its last status."""
    for _ in range(rounds):
        got = await call(client, "wait_for_generation", run=run, timeout_s=30)
        if not got["live"] or got["outcome"] == "run_ended":
            status = await call(client, "run_status", run=run)
            if not status["live"] and status["status"] != "finishing":
                return status
    raise AssertionError(f"run {run} did not end")
