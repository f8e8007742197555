"""The ``intuitf`` command. Each sub-command lives in its own module with a ``register(app)``.

Errors a user can cause are printed as one clear message, never as a traceback.
"""

from __future__ import annotations

import importlib
import signal
import sys
import threading

import typer
from rich.console import Console
from rich.markup import escape

from intuitf.errors import IntuitfError

app = typer.Typer(
    name="intuitf",
    help="Design transfer functions for direct volume rendering from what you want.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _print_version(value: bool) -> None:
    if value:
        from intuitf import __version__

        typer.echo(f"intuitf {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(
        False,
        "--version",
        callback=_print_version,
        is_eager=True,
        help="Show intuitf's version and exit.",
    ),  # fmt: skip
) -> None:
    """Design transfer functions for direct volume rendering from what you want."""


#: Modules under intuitf.cli that contribute commands (each has ``register(app)``).
COMMAND_MODULES = [
    "intuitf.cli.volume_cmds",
    "intuitf.cli.judge_cmds",
    "intuitf.cli.render_cmds",
    "intuitf.cli.export_cmds",
    "intuitf.cli.optimize_cmds",
    "intuitf.cli.serve_cmds",
    "intuitf.cli.batch_cmds",
    "intuitf.cli.mcp_cmds",
]

for _name in COMMAND_MODULES:
    importlib.import_module(_name).register(app)

err_console = Console(stderr=True)


def _click_flavours() -> list:
    """The click modules whose exceptions Typer may raise: the vendored ``typer._click`` of
    newer Typer releases and, when installed, the stand-alone ``click`` of older ones."""
    mods = []
    for name in ("typer._click.exceptions", "click.exceptions"):
        try:
            mods.append(importlib.import_module(name))
        except ImportError:
            continue
    return mods


def _usage_exception_classes() -> tuple[tuple[type, ...], tuple[type, ...]]:
    """(ClickException classes, Abort classes) of every click flavour present."""
    mods = _click_flavours()
    shown = tuple(m.ClickException for m in mods if hasattr(m, "ClickException"))
    aborts = tuple(m.Abort for m in mods if hasattr(m, "Abort"))
    aborts += (typer.Abort,)
    return shown, aborts


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the app and turn user errors into a message and exit code 2.

    Usage errors (a mistyped command or option, a value not among the choices) are shown
    the way click shows them, whichever click Typer was built on, never as a traceback.
    """
    try:
        rc = app(args=argv, standalone_mode=False)
        # With standalone_mode off, click returns a command's typer.Exit code instead of exiting.
        if isinstance(rc, int) and rc != 0:
            sys.exit(rc)
    except IntuitfError as exc:
        # escape(): messages quote paths and config snippets such as "[api_keys]". Soft wrap:
        # the terminal wraps long lines; Rich would break the paths and commands they quote
        # with newlines (a log or a copied "--resume PATH" then has a broken path).
        err_console.print(
            f"[bold red]error:[/] {escape(exc.message)}", highlight=False, soft_wrap=True
        )
        if exc.hint:
            err_console.print(
                f"[yellow]what to do:[/] {escape(exc.hint)}", highlight=False, soft_wrap=True
            )
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print("[yellow]Interrupted.[/] Everything finished so far was kept.")
        sys.exit(130)
    except SystemExit:
        raise
    except Exception as exc:  # click's usage errors and the like
        shown, aborts = _usage_exception_classes()
        if isinstance(exc, shown):
            exc.show()  # type: ignore[attr-defined]
            code = getattr(exc, "exit_code", 2)
            sys.exit(code if isinstance(code, int) else 2)
        if isinstance(exc, aborts):
            err_console.print("[yellow]Aborted.[/]")
            sys.exit(130)
        raise


def console_main() -> None:
    """The process entry point (``intuitf`` and ``python -m intuitf``): :func:`main`, and then
    a Ctrl-C that arrives after the command is over ends the process silently.

    Everything is saved by then; the interpreter's shutdown (joining worker threads) would
    otherwise print a KeyboardInterrupt traceback for a key pressed a moment too late.
    """
    try:
        main()
    finally:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_DFL)
