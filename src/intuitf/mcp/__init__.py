"""intuitf for agents: a Model Context Protocol server over the Session service.

``intuitf mcp`` (see :mod:`intuitf.cli.mcp_cmds`) serves the tools of :mod:`.tools` with the
official ``mcp`` SDK. Modules: :mod:`.roots` (the folders it may use and the path check),
:mod:`.camera` (orbit and VTK cameras), :mod:`.pictures` (images sized for clients),
:mod:`.volumes` (open volumes and their current TFs), :mod:`.service` and :mod:`.runs` (what
the tools do, over :class:`~intuitf.session.Session` and :class:`~intuitf.session.RunStore`),
:mod:`.server` (transports).
"""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:
    from intuitf.mcp.roots import Roots
    from intuitf.mcp.server import build_server
    from intuitf.mcp.service import McpConfig, McpService

_EXPORTS = {
    "Roots": "intuitf.mcp.roots",
    "build_server": "intuitf.mcp.server",
    "McpConfig": "intuitf.mcp.service",
    "McpService": "intuitf.mcp.service",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = ["McpConfig", "McpService", "Roots", "build_server"]
