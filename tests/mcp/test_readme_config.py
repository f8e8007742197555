"""The README's client configuration starts a working server: its JSON entry, with the
placeholder folders replaced, is what a stdio client launches; and the HTTP transport keeps
``intuitf serve``'s token and Host rules."""

from __future__ import annotations

import asyncio
import json
import re
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from mcp_util import call

from mcp import Client, StdioServerParameters

README = Path(__file__).resolve().parents[2] / "README.md"

pytestmark = pytest.mark.slow  # each starts a server process


def _entry() -> dict:
    text = README.read_text(encoding="utf-8")
    blocks = [b for b in re.findall(r"```json\n(.*?)```", text, flags=re.S) if "mcpServers" in b]
    assert len(blocks) == 1, "one configuration entry in the README"
    return json.loads(blocks[0])["mcpServers"]["intuitf"]


def test_readme_entry_starts_a_server_a_stdio_client_can_use(folders):
    entry = _entry()
    assert entry["command"] == "intuitf" and entry["args"][0] == "mcp"
    command = shutil.which("intuitf")
    if command is None:
        pytest.skip("the intuitf command is not on PATH (install the package)")
    places = {"/path/to/volumes": folders["data"], "/path/to/runs": folders["runs"],
              "/path/to/out": folders["out"]}  # fmt: skip
    args = [str(places.get(a, a)) for a in entry["args"]]
    assert set(places.values()) <= {Path(a) for a in args}, "every folder is a placeholder"

    async def main():
        params = StdioServerParameters(command=command, args=args)
        async with Client(params) as client:
            listed = await call(client, "list_volumes")
            foot = await call(client, "open_volume", path=listed["files"][0]["path"])
            return await call(client, "render", volume=foot["id"], size=64)

    shot = asyncio.run(main())
    assert Path(shot["path"]).is_file() and shot["image"]["width"] == 64


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_http_transport_needs_the_token_and_a_local_host(folders):
    port = _free_port()
    token = "test-token-0123456789abcdef"
    cmd = [sys.executable, "-m", "intuitf", "mcp", "--http", "--port", str(port),
           "--data", str(folders["data"]), "--runs", str(folders["runs"]),
           "--out", str(folders["out"])]  # fmt: skip
    proc = subprocess.Popen(cmd, env={**__import__("os").environ, "INTUITF_MCP_TOKEN": token},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    url = f"http://127.0.0.1:{port}/mcp"
    try:
        deadline = time.monotonic() + 60
        while True:  # until it listens
            try:
                r = httpx.post(url, json={}, timeout=2)
                break
            except httpx.TransportError:
                assert proc.poll() is None, proc.stderr.read().decode()
                assert time.monotonic() < deadline, "the server did not start"
                time.sleep(0.1)
        assert r.status_code == 401 and "token" in r.json()["detail"]
        bad_host = httpx.post(url, json={}, headers={"Host": "evil.example:80",
                                                     "Authorization": f"Bearer {token}"})  # fmt: skip
        assert bad_host.status_code == 400
        cross = httpx.post(url, json={}, headers={"Origin": "http://evil.example",
                                                  "Authorization": f"Bearer {token}"})  # fmt: skip
        assert cross.status_code == 403

        async def main():
            import httpx2
            from mcp.client.streamable_http import streamable_http_client

            headers = {"Authorization": f"Bearer {token}"}
            async with httpx2.AsyncClient(headers=headers, timeout=60) as http:
                async with Client(streamable_http_client(url, http_client=http)) as client:
                    vid = (await call(client, "open_volume", path="phantom", max_dim=32))["id"]
                    return await call(client, "render", volume=vid, size=48)

        shot = asyncio.run(main())
        assert shot["image"]["width"] == 48
    finally:
        proc.terminate()
        proc.wait(timeout=30)
