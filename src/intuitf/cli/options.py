"""Reusable command-line options for reading a volume, and the call that reads it.

A command that takes a volume declares the argument and the options with these aliases and
hands them to :func:`open_volume`::

    from intuitf.cli import options as vo

    @app.command()
    def render(
        volume: vo.VolumeArg,
        shape: vo.ShapeOpt = None,
        dtype: vo.DtypeOpt = None,
        byte_order: vo.ByteOrderOpt = None,
        spacing: vo.SpacingOpt = None,
        max_dim: vo.MaxDimOpt = None,
    ) -> None:
        vol = vo.open_volume(volume, shape, dtype, byte_order, spacing, max_dim)

``VOLUME`` may be a file, a folder (DICOM series or TIFF slices), or ``phantom`` /
``builtin:phantom`` for the built-in phantom. Bad values raise
:class:`~intuitf.errors.VolumeError`, which the ``intuitf`` entry point prints without a
traceback (exit code 2).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from enum import StrEnum
from typing import TYPE_CHECKING, Annotated, Any

import typer

from intuitf.errors import VolumeError

if TYPE_CHECKING:
    from intuitf.volume import Volume

_PANEL = "Volume options"

#: The view every command uses unless told otherwise (render, optimize): the one default view
#: of every front end (:mod:`intuitf.render.camera`). A sketch drawn on an ``intuitf render``
#: picture is judged from the camera recorded in that picture, whatever these say.
from intuitf.render.camera import DEFAULT_AZIMUTH, DEFAULT_ELEVATION  # noqa: E402,F401


def choices(name: str, values: Iterable[str]) -> type[StrEnum]:
    """A string Enum of ``values`` for a choice-valued option.

    Typer checks the option against it before the command runs and, for any other value,
    prints a usage error that lists the valid ones (exit code 2). The command receives a
    member, which is a ``str`` equal to its value.
    """
    return StrEnum(name, [(re.sub(r"\W", "_", v).upper() or "_", v) for v in values])


#: Voxel types of raw files, by their canonical names.
Dtype = choices(
    "Dtype",
    ("uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64", "float16",
     "float32", "float64"),
)  # fmt: skip
ByteOrder = choices("ByteOrder", ("little", "big"))


def _explorer_methods() -> tuple[str, ...]:
    from intuitf.explorer.methods import METHODS

    return tuple(METHODS)


def _protocols() -> tuple[str, ...]:
    from typing import get_args

    from intuitf.evaluator.tournament import Protocol

    return get_args(Protocol)


#: ``optimize --explorer``: the search methods; ``--protocol``: the tournament protocols.
Explorer = choices("Explorer", _explorer_methods())
Protocol = choices("Protocol", _protocols())

#: The search options ``optimize`` and ``batch`` share.
ExplorerOpt = Annotated[
    Explorer,
    typer.Option("--explorer", case_sensitive=False, help="Search method."),
]
ProtocolOpt = Annotated[
    Protocol,
    typer.Option("--protocol", case_sensitive=False, help="Tournament protocol."),
]

VolumeArg = Annotated[
    str,
    typer.Argument(
        metavar="VOLUME",
        help="Volume file or folder (raw, raw.gz, nrrd, nii, mha, vti, tiff, npy, cvol, DICOM "
        "folder), or 'phantom' for the built-in phantom.",
        show_default=False,
    ),
]
ShapeOpt = Annotated[
    str | None,
    typer.Option(
        "--shape",
        metavar="X,Y,Z",
        help="Grid size of a headerless raw file (default: from its name, e.g. foot_256x256x256_uint8.raw).",
        rich_help_panel=_PANEL,
    ),
]
DtypeOpt = Annotated[
    Dtype | None,
    typer.Option(
        "--dtype",
        help="Voxel type of a raw file (default: from its name or its JSON sidecar).",
        case_sensitive=False,
        rich_help_panel=_PANEL,
    ),
]
ByteOrderOpt = Annotated[
    ByteOrder | None,
    typer.Option(
        "--byte-order",
        help="Byte order of a raw file (default: little, or its sidecar's).",
        case_sensitive=False,
        rich_help_panel=_PANEL,
    ),
]
SpacingOpt = Annotated[
    str | None,
    typer.Option(
        "--spacing",
        metavar="X,Y,Z",
        help="Voxel size along x, y, z; overrides the file's own spacing.",
        rich_help_panel=_PANEL,
    ),
]
MaxDimOpt = Annotated[
    int | None,
    typer.Option(
        "--max-dim",
        metavar="N",
        help="Downsample so that no axis has more than N voxels (for large volumes).",
        rich_help_panel=_PANEL,
    ),
]


def parse_triple(text: str | None, what: str, kind: type = float) -> tuple | None:
    """Parse ``"X,Y,Z"`` (or ``"XxYxZ"``) into three numbers of ``kind``; None passes through."""
    if text is None:
        return None
    parts = (
        [p for p in re.split(r"[,x\s]+", text.strip()) if p]
        if kind is int
        else [p for p in re.split(r"[,\s]+", text.strip()) if p]
    )
    flag = "--" + what
    try:
        values = tuple(kind(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(v > 0 for v in values):
        example = "256,256,128" if kind is int else "1,1,2.5"
        raise VolumeError(
            f"{flag} needs three positive {'integers' if kind is int else 'numbers'} X,Y,Z, "
            f"got {text!r}.",
            f"Write it like {flag} {example}.",
        )
    return values


def volume_kwargs(
    shape: str | None = None,
    dtype: str | None = None,
    byte_order: str | None = None,
    spacing: str | None = None,
    max_dim: int | None = None,
) -> dict[str, Any]:
    """Turn the option values into keyword arguments for :func:`intuitf.volume.load_volume`."""
    if byte_order is not None and str(byte_order).strip().lower() not in ("little", "big"):
        raise VolumeError(
            f"--byte-order must be 'little' or 'big', got {byte_order!r}.",
            "Use --byte-order little or --byte-order big.",
        )
    if max_dim is not None and max_dim < 2:
        raise VolumeError(
            f"--max-dim must be at least 2, got {max_dim}.", "Use e.g. --max-dim 256."
        )
    kw: dict[str, Any] = {
        "shape": parse_triple(shape, "shape", int),
        "dtype": str(dtype.value if isinstance(dtype, StrEnum) else dtype) if dtype else None,
        "byte_order": str(byte_order).strip().lower() if byte_order else None,
        "spacing": parse_triple(spacing, "spacing", float),
        "max_dim": max_dim,
    }
    return {k: v for k, v in kw.items() if v is not None}


def open_volume(
    volume: str,
    shape: str | None = None,
    dtype: str | None = None,
    byte_order: str | None = None,
    spacing: str | None = None,
    max_dim: int | None = None,
) -> Volume:
    """Read ``volume`` (a path, or ``phantom`` / ``builtin:phantom``) with the CLI options."""
    from intuitf.volume import load_volume

    return load_volume(volume, **volume_kwargs(shape, dtype, byte_order, spacing, max_dim))
