"""``intuitf mcp``: the Model Context Protocol server, for agents (Claude, Codex, Cursor, ...)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from intuitf.errors import IntuitfError


def register(app: typer.Typer) -> None:
    @app.command()
    def mcp(
        data: Annotated[
            list[Path] | None,
            typer.Option(
                "--data",
                help="Folder of volumes (and pictures) agents may read; repeat for more "
                "(default: $INTUITF_DATA if set).",
            ),  # fmt: skip
        ] = None,
        runs: Annotated[
            Path, typer.Option("--runs", help="Folder of the runs agents start and read.")
        ] = Path("runs"),
        out: Annotated[
            Path,
            typer.Option("--out", help="Folder agents' exports and pictures are written to."),
        ] = Path("mcp-out"),
        evaluator: Annotated[
            str,
            typer.Option(
                "--evaluator",
                "-e",
                help="Default judge of runs: metric, openai:MODEL, gemini:MODEL, ollama:MODEL, "
                "... or a server URL.",
            ),  # fmt: skip
        ] = "metric",
        budget_usd: Annotated[
            float | None,
            typer.Option(
                "--budget-usd",
                min=0,
                help="Money budget of each model-judged run that sets none itself.",
            ),  # fmt: skip
        ] = None,
        budget_calls: Annotated[
            int | None,
            typer.Option(
                "--budget-calls",
                min=0,
                help="Call budget of each model-judged run that sets none itself.",
            ),  # fmt: skip
        ] = None,
        max_runs: Annotated[int, typer.Option("--max-runs", min=1, help="Runs going at once.")] = 2,
        max_dim: Annotated[
            int | None,
            typer.Option(
                "--max-dim",
                metavar="N",
                help="Downsample volumes to at most N "
                "voxels per axis unless a tool asks otherwise.",
            ),  # fmt: skip
        ] = None,
        device: Annotated[
            str, typer.Option("--device", help="Where to render: auto, cpu or cuda.")
        ] = "auto",
        picture_side: Annotated[
            int,
            typer.Option(
                "--picture-side",
                min=64,
                max=1568,
                help="Longest side of the pictures "
                "sent to agents (their files keep the full size).",
            ),  # fmt: skip
        ] = 768,
        http: Annotated[
            bool,
            typer.Option(
                "--http", help="Serve streamable HTTP on 127.0.0.1 (with a token) instead of stdio."
            ),  # fmt: skip
        ] = False,
        port: Annotated[int, typer.Option("--port", help="HTTP port (0: a free one).")] = 0,
    ) -> None:
        """Serve intuitf's tools to agents over MCP (stdio by default)."""
        from intuitf.mcp.roots import Roots
        from intuitf.mcp.service import McpConfig

        if not data and os.environ.get("INTUITF_DATA"):
            data = [Path(os.environ["INTUITF_DATA"])]
        for d in data or []:
            if not d.is_dir():
                raise IntuitfError(f"--data {d}: no such folder.", "Give a folder of volumes.")
        if device not in ("auto", "cpu", "cuda"):
            raise IntuitfError(f"--device {device!r}: use auto, cpu or cuda.")
        for folder, flag in ((runs, "--runs"), (out, "--out")):
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:  # a desktop client may start us in a folder we cannot write
                raise IntuitfError(
                    f"{flag} {folder}: cannot make this folder ({exc.strerror or exc}).",
                    f"Give {flag} an absolute path to a folder you can write.",
                ) from None
        config = McpConfig(
            roots=Roots(data=list(data or []), runs=runs, out=out),
            evaluator=evaluator,
            budget_usd=budget_usd,
            budget_calls=budget_calls,
            max_live=max_runs,
            max_dim=max_dim,
            device=device,
            picture_side=picture_side,
        )
        if not http:
            from intuitf.mcp.server import run_stdio

            run_stdio(config)
            return
        from intuitf.cli.serve_cmds import allowed_hosts, free_port
        from intuitf.mcp.server import run_http
        from intuitf.web.security import new_token

        host = "127.0.0.1"
        try:
            port = port or free_port(host)
        except OSError as exc:
            raise IntuitfError(f"Cannot bind to {host}: {exc.strerror or exc}.") from None
        token = os.environ.get("INTUITF_MCP_TOKEN") or new_token()
        # stdout stays clean for tools that parse it; the address goes to stderr.
        print(f"intuitf MCP server at http://{host}:{port}/mcp", file=sys.stderr)
        print(f"    header: Authorization: Bearer {token}", file=sys.stderr)
        print("Press Ctrl-C to stop (running runs are stopped between matches and kept).",
              file=sys.stderr)  # fmt: skip
        run_http(config, host, port, token, allowed_hosts(host, port))
