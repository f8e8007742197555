"""The MCP server: the tools of :mod:`.tools` on the official SDK's ``MCPServer``, over stdio
(what desktop clients start) or streamable HTTP on loopback behind ``intuitf serve``'s guard
(a per-launch token, Host and Origin checks, secrets blanked out of responses)."""

from __future__ import annotations

import logging
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from mcp.server.mcpserver import MCPServer

from intuitf.mcp.service import McpConfig, McpService
from intuitf.mcp.tools import Results, forbid_unknown_arguments, register

INSTRUCTIONS = """\
intuitf finds transfer functions (TFs) for direct volume rendering from what you want.
Typical session: list_volumes -> open_volume (returns a volume id) -> describe_volume (materials)
-> render (a picture of the current TF) -> start_run with an intent in words (returns a run name
at once; the search runs in the background) -> wait_for_generation / run_status -> gallery (the
best candidates with ids like RUN/g003-007, ratings and the judge's reasons) -> prefer /
choose_best to steer -> select_feature (x, y on a candidate's picture) -> refine (words for the
selected features) -> export (ParaView, 3D Slicer, VTK, ImageVis3D, JSON, PNG).
Cameras: orbit {azimuth, elevation, zoom} or VTK {position, focal_point, view_up}.
Pictures come back as images with their full-size file path in the JSON.
Files are read only under the server's data folders and written only under its output folder.
"""


def build_server(config: McpConfig) -> tuple[MCPServer, McpService]:
    """The MCP server with every intuitf tool, and the service behind it."""
    import intuitf
    from intuitf.web.security import find_secrets

    service = McpService(config)
    results = Results(find_secrets(), picture_side=config.picture_side)

    @asynccontextmanager
    async def lifespan(_server: MCPServer) -> AsyncIterator[None]:
        try:
            yield None
        finally:
            # The client went away: stop runs between matches; they continue on resume.
            await service.close()

    server = MCPServer(
        "intuitf",
        title="intuitf: transfer functions from words",
        instructions=INSTRUCTIONS,
        version=intuitf.__version__,
        lifespan=lifespan,
        log_level="WARNING",
    )
    register(server, service, results)
    forbid_unknown_arguments(server)
    return server, service


def run_stdio(config: McpConfig) -> None:
    """Serve on stdin/stdout until the client closes them."""
    import anyio

    _quiet_logs()
    server, service = build_server(config)
    service.warm_up()
    anyio.run(server.run_stdio_async)


def http_app(config: McpConfig, token: str, allowed_hosts: list[str]):
    """The streamable-HTTP ASGI app at ``/mcp``, behind the web app's security middleware."""
    from mcp.server.transport_security import TransportSecuritySettings

    from intuitf.web.security import SecurityMiddleware

    server, service = build_server(config)
    service.warm_up()
    # The middleware checks Host, Origin and the token; the SDK's own check would refuse the
    # same things again with other messages.
    inner = server.streamable_http_app(
        transport_security=TransportSecuritySettings(enable_dns_rebinding_protection=False)
    )
    return SecurityMiddleware(inner, token=token, allowed_hosts=allowed_hosts)


def run_http(config: McpConfig, host: str, port: int, token: str, allowed_hosts: list[str]) -> None:
    """Serve streamable HTTP on ``host:port`` until interrupted."""
    import uvicorn

    _quiet_logs()
    app = http_app(config, token, allowed_hosts)
    uvicorn.Server(
        uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="on")
    ).run()


def _quiet_logs() -> None:
    """Warnings and errors to stderr (stdout is the protocol's on stdio); no request logs,
    whose arguments could hold what an agent typed."""
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="intuitf mcp: %(levelname)s %(name)s: %(message)s")  # fmt: skip
    logging.getLogger("mcp").setLevel(logging.WARNING)
