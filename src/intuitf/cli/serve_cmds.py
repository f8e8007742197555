"""``intuitf serve``: the interactive system in the browser, on this machine."""

from __future__ import annotations

import errno
import os
import socket
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from intuitf.cli import judge_options as jo
from intuitf.cli import options as vo
from intuitf.errors import IntuitfError

console = Console()

LOOPBACK = ("127.0.0.1", "localhost", "::1")


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on now."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def allowed_hosts(host: str, port: int) -> list[str]:
    """The Host header values the server answers: loopback names, and ``host`` when given."""
    out = [f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}"]
    if host not in LOOPBACK and host not in ("0.0.0.0", "::"):
        out.append(f"{host}:{port}")
    if host in ("0.0.0.0", "::"):
        out.append(f"{socket.gethostname()}:{port}")
    return out


def check_port(host: str, port: int) -> None:
    """A plain error when ``port`` is taken (another server listens there)."""
    bind = host if host not in ("0.0.0.0", "::", "localhost") else "127.0.0.1"
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    with socket.socket(family) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((bind, port))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise IntuitfError(
                    f"Port {port} is taken: another program (perhaps another intuitf serve) "
                    "listens there.",
                    "Stop it, give another --port, or leave --port out for a free one.",
                ) from None
            raise IntuitfError(f"Cannot listen on {host}:{port}: {exc.strerror or exc}.") from None


def register(app: typer.Typer) -> None:
    @app.command()
    def serve(
        volumes: Annotated[
            list[str] | None,
            typer.Argument(help="Volume files to offer (the phantom is always there)."),
        ] = None,
        data: Annotated[
            Path | None,
            typer.Option(
                "--data",
                help="Offer every volume file in this folder (default: $INTUITF_DATA if set).",
            ),  # fmt: skip
        ] = None,
        evaluator: Annotated[
            str,
            typer.Option(
                "--evaluator",
                "-e",
                help="Judge of new runs: metric, openai:MODEL, "
                "gemini:MODEL, ollama:MODEL, ... or a server URL.",
            ),  # fmt: skip
        ] = "metric",
        runs: Annotated[
            Path, typer.Option("--runs", help="Folder of the runs (the history).")
        ] = Path("runs"),
        port: Annotated[
            int, typer.Option("--port", min=0, max=65535, help="Port (0: a free one).")
        ] = 0,
        host: Annotated[
            str, typer.Option("--host", help="Address to bind (default loopback only).")
        ] = "127.0.0.1",
        no_browser: Annotated[
            bool, typer.Option("--no-browser", help="Do not open a browser.")
        ] = False,
        max_upload_mb: Annotated[
            int, typer.Option("--max-upload-mb", min=1, help="Largest upload (MiB).")
        ] = 512,
        max_dim: Annotated[
            int | None,
            typer.Option(
                "--max-dim",
                metavar="N",
                help="Downsample volumes to at most N "
                "voxels per axis (faster views of large data).",
            ),  # fmt: skip
        ] = None,
        device: Annotated[
            str,
            typer.Option(
                "--device",
                metavar="auto|cpu|cuda",
                help="Where to render: cuda (an NVIDIA GPU), cpu, or auto (the GPU when "
                "usable). New runs take it; a run's views render on the run's device.",
            ),  # fmt: skip
        ] = "auto",
        spacing: vo.SpacingOpt = None,
        token: Annotated[
            str | None,
            typer.Option(
                "--token",
                envvar="INTUITF_TOKEN",
                help="Access token (default: the one kept in the runs folder, made on the first "
                "serve, so open pages survive a restart).",
            ),  # fmt: skip
        ] = None,
        max_concurrency: jo.MaxConcurrencyOpt = None,
        max_output_tokens: jo.MaxOutputTokensOpt = None,
        reasoning_effort: jo.ReasoningEffortOpt = None,
        price: jo.PriceOpt = None,
        unpriced: jo.UnpricedOpt = False,
    ) -> None:
        """Start the web app: watch runs, steer them, and pick, refine and export results."""
        from intuitf.web.app import create_app, make_server
        from intuitf.web.security import kept_token

        if data is None and os.environ.get("INTUITF_DATA"):
            data = Path(os.environ["INTUITF_DATA"])
        if data is not None and not data.is_dir():
            raise IntuitfError(f"--data {data}: no such folder.", "Give a folder of volumes.")
        if Path(runs).exists() and not Path(runs).is_dir():
            raise IntuitfError(
                f"--runs {runs} is a file, not a folder.", "Give the folder that holds the runs."
            )
        for v in volumes or []:
            if v not in ("phantom", "builtin:phantom") and not Path(v).exists():
                raise IntuitfError(f"{v}: no such volume file.", "Check the path.")
        if host not in LOOPBACK:
            console.print(
                f"[yellow]warning:[/] binding to {host}: other machines can reach this server "
                "(the token still guards it; anyone who sees the URL can use it)."
            )
        try:
            port = port or free_port(host if host not in ("0.0.0.0", "::") else "127.0.0.1")
        except OSError as exc:
            raise IntuitfError(f"Cannot bind to {host}: {exc.strerror or exc}.") from None
        check_port(host, port)  # before the address is printed: a taken port is said plainly
        reader = vo.volume_kwargs(spacing=spacing)
        from intuitf.render.device import select_device

        select_device(device)  # a missing GPU is reported before the server starts
        judge_options = jo.judge_options(
            max_concurrency, max_output_tokens, reasoning_effort, price, unpriced
        )
        if token is not None and len(token) < 16:
            raise IntuitfError("--token must be at least 16 characters.", "Use a long random one.")
        token = token or kept_token(Path(runs))
        app = create_app(
            runs,
            list(volumes or []),
            data,
            evaluator=evaluator,
            token=token,
            allowed_hosts=allowed_hosts(host, port),
            max_upload_bytes=max_upload_mb * 1024 * 1024,
            max_dim=max_dim,
            spacing=reader.get("spacing"),
            device=None if device == "auto" else device,
            judge_options=judge_options,
        )
        shown = "127.0.0.1" if host in ("0.0.0.0", "::", "localhost") else host
        shown = f"[{shown}]" if ":" in shown else shown
        url = f"http://{shown}:{port}/?token={token}"
        console.print(f"intuitf is serving [bold]{Path(runs).resolve()}[/] at")
        console.print(f"    {url}", highlight=False, soft_wrap=True)
        console.print("Press Ctrl-C to stop (running runs are stopped between matches and kept).")
        if not no_browser:
            try:
                import webbrowser

                webbrowser.open(url)
            except Exception:  # no browser on this machine: the printed URL is enough
                pass
        make_server(app, host, port).run()
