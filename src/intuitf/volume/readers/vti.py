"""VTK XML image data (``.vti``), parsed with the standard library, numpy and zlib/lzma/lz4.

VTK is not needed at run time. Supported: ``format="ascii"``, inline ``"binary"`` (base64) and
``"appended"`` data with ``encoding="raw"`` or ``"base64"``; ``header_type`` UInt32 or UInt64;
no compressor, ``vtkZLibDataCompressor``, ``vtkLZMADataCompressor`` or ``vtkLZ4DataCompressor``;
little- or big-endian; several pieces. The point-data scalars (the ``Scalars`` attribute, or the
first point array; cell data when there is no point data) are read. VTK stores x fastest, so the
array comes out ``[z, y, x]``; ``Spacing`` is along (x, y, z). ``Origin`` and ``Direction`` are
not applied.
"""

from __future__ import annotations

import base64
import binascii
import lzma
import math
import xml.etree.ElementTree as ET
import zlib

import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest

_TYPES = {
    "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4",
    "UInt32": "u4", "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8",
    "Char": "i1", "UnsignedChar": "u1", "Short": "i2", "UnsignedShort": "u2",
}  # fmt: skip


class _Corrupt(Exception):
    """Internal: the data of one array does not match what its header declares."""


def _decompress(name: str | None, block: bytes, raw_size: int) -> bytes:
    if name == "vtkZLibDataCompressor":
        return zlib.decompress(block)
    if name == "vtkLZMADataCompressor":
        return lzma.decompress(block)
    if name == "vtkLZ4DataCompressor":
        import lz4.block

        return lz4.block.decompress(block, uncompressed_size=raw_size)
    raise VolumeError(f"unsupported VTK compressor {name!r}.")


class _Layout:
    """What the VTKFile element says about how binary blocks are laid out."""

    def __init__(self, root: ET.Element) -> None:
        self.big = root.get("byte_order", "LittleEndian") == "BigEndian"
        ht = root.get("header_type", "UInt32")
        if ht not in ("UInt32", "UInt64"):
            raise _Corrupt(f"unsupported header_type {ht!r}")
        self.hsize = 4 if ht == "UInt32" else 8
        self.htype = np.dtype(("<" if not self.big else ">") + ("u4" if self.hsize == 4 else "u8"))
        self.compressor = root.get("compressor")

    def words(self, b: bytes, n: int) -> list[int]:
        if len(b) < n * self.hsize:
            raise _Corrupt("block header is truncated")
        return [int(v) for v in np.frombuffer(b[: n * self.hsize], dtype=self.htype)]

    # -- raw bytes (appended raw) --------------------------------------------------------
    def block_from_bytes(self, buf: bytes, pos: int) -> bytes:
        if self.compressor is None:
            (n,) = self.words(buf[pos : pos + self.hsize], 1)
            data = buf[pos + self.hsize : pos + self.hsize + n]
            if len(data) != n:
                raise _Corrupt(f"expected {n} data bytes, found {len(data)}")
            return data
        nb, bs, last = self.words(buf[pos : pos + 3 * self.hsize], 3)
        sizes = self.words(buf[pos + 3 * self.hsize : pos + (3 + nb) * self.hsize], nb)
        start = pos + (3 + nb) * self.hsize
        return self._inflate(buf[start : start + sum(sizes)], nb, bs, last, sizes)

    # -- base64 text (inline binary, appended base64) -------------------------------------
    def block_from_base64(self, text: bytes) -> bytes:
        s = b"".join(text.split())
        hs = self.hsize

        def chars(nbytes: int) -> int:
            return 4 * math.ceil(nbytes / 3)

        if self.compressor is None:
            head_len = hs
            (n,) = self.words(_b64(s[: chars(hs)]), 1)
            payload_len = n
        else:
            nb, bs, last = self.words(_b64(s[: chars(3 * hs)]), 3)  # 3*hs bytes: exact prefix
            head_len = (3 + nb) * hs
            sizes = self.words(_b64(s[: chars(head_len)]), 3 + nb)[3:]
            payload_len = sum(sizes)
        hl = chars(head_len)
        # VTK encodes the header and the data as separate base64 runs; a run that does not
        # fill its last group ends in '=' padding. Without padding both readings agree.
        if b"=" in s[:hl]:
            payload = _b64(s[hl : hl + chars(payload_len)])
        else:
            payload = _b64(s[: chars(head_len + payload_len)])[head_len:]
        if len(payload) < payload_len:
            raise _Corrupt(f"expected {payload_len} data bytes, found {len(payload)}")
        if self.compressor is None:
            return payload[:payload_len]
        return self._inflate(payload, nb, bs, last, sizes)

    def _inflate(self, comp: bytes, nb: int, bs: int, last: int, sizes: list[int]) -> bytes:
        if len(comp) < sum(sizes):
            raise _Corrupt("compressed data is truncated")
        out, pos = [], 0
        for i, cs in enumerate(sizes):
            raw = last if (i == nb - 1 and last) else bs
            out.append(_decompress(self.compressor, comp[pos : pos + cs], raw))
            pos += cs
        return b"".join(out)


def _b64(s: bytes) -> bytes:
    try:
        return base64.b64decode(s, validate=False)
    except (binascii.Error, ValueError) as exc:
        raise _Corrupt(f"invalid base64 data ({exc})") from None


def _extent(text: str | None) -> tuple[int, ...]:
    vals = tuple(int(v) for v in (text or "").split())
    if len(vals) != 6:
        raise _Corrupt(f"invalid extent {text!r}")
    return vals


def _pick_array(piece: ET.Element) -> tuple[ET.Element, bool]:
    """The scalar DataArray of a piece and whether it is point data (else cell data)."""
    for tag, is_point in (("PointData", True), ("CellData", False)):
        sec = piece.find(tag)
        if sec is None:
            continue
        arrays = sec.findall("DataArray")
        if not arrays:
            continue
        active = sec.get("Scalars")
        for a in arrays:
            if active and a.get("Name") == active:
                return a, is_point
        return arrays[0], is_point
    raise _Corrupt("the file holds no point or cell data arrays")


def read(request: ReadRequest) -> RawArray:
    """Read a ``.vti`` file."""
    path = request.path
    try:
        return _read(request)
    except _Corrupt as exc:
        raise VolumeError(
            f"{path}: the VTK image data is corrupt or truncated ({exc}).",
            "Check that the file is complete, or save it again from its source.",
        ) from None
    except (ET.ParseError, zlib.error, lzma.LZMAError, UnicodeDecodeError) as exc:
        raise VolumeError(
            f"{path}: not a readable .vti file ({exc}).",
            "Check that the file is complete and is VTK XML ImageData.",
        ) from None


def _read(request: ReadRequest) -> RawArray:
    path = request.path
    buf = path.read_bytes()
    # Appended raw data is binary and not valid XML: parse only the part before it.
    cut = buf.find(b"<AppendedData")
    appended = b""
    encoding = "raw"
    if cut >= 0:
        tag_end = buf.index(b">", cut)
        enc = ET.fromstring(buf[cut:tag_end].rstrip(b"/") + b"/>").get("encoding", "base64")
        encoding = enc
        start = buf.index(b"_", tag_end) + 1
        appended = buf[start:]
        xml = buf[:cut] + b"</VTKFile>"
    else:
        xml = buf
    root = ET.fromstring(xml)
    if root.tag != "VTKFile" or root.get("type") != "ImageData":
        raise _Corrupt(f"expected a VTKFile of type ImageData, got {root.get('type')!r}")
    layout = _Layout(root)
    image = root.find("ImageData")
    if image is None:
        raise _Corrupt("no ImageData element")
    whole = _extent(image.get("WholeExtent"))
    spacing = tuple(float(v) for v in (image.get("Spacing") or "1 1 1").split())
    pieces = image.findall("Piece")
    if not pieces:
        raise _Corrupt("no Piece element")

    out: np.ndarray | None = None
    notes: list[str] = []
    for piece in pieces:
        ext = _extent(piece.get("Extent"))
        arr_el, is_point = _pick_array(piece)
        k = 0 if is_point else 1  # cells are one fewer than points along each axis
        dims = tuple(max(1, ext[2 * i + 1] - ext[2 * i] + 1 - k) for i in range(3))
        wdims = tuple(max(1, whole[2 * i + 1] - whole[2 * i] + 1 - k) for i in range(3))
        tname = arr_el.get("type", "")
        if tname not in _TYPES:
            raise VolumeError(
                f"{path}: unsupported VTK array type {tname!r}.",
                "Save the scalars as an integer or float type.",
            )
        ncomp = int(arr_el.get("NumberOfComponents", "1"))
        if ncomp != 1:
            raise VolumeError(
                f"{path}: the array {arr_el.get('Name')!r} has {ncomp} components; a volume "
                "needs one value per voxel.",
                "Save a single scalar array (for example its magnitude).",
            )
        dtype = np.dtype(("<" if not layout.big else ">") + _TYPES[tname])
        if out is None:
            request.reserve(wdims, dtype)  # type: ignore[arg-type]
            out = np.zeros(wdims[::-1], dtype=dtype.newbyteorder("="))
            if not is_point:
                notes.append("The file has cell data only; reading it as the voxel grid.")
        fmt = arr_el.get("format", "ascii")
        count = dims[0] * dims[1] * dims[2]
        if fmt == "ascii":
            values = np.array((arr_el.text or "").split(), dtype=dtype.newbyteorder("="))
        else:
            if fmt == "binary":
                block = layout.block_from_base64((arr_el.text or "").encode("ascii"))
            elif fmt == "appended":
                off = int(arr_el.get("offset", "0"))
                if encoding == "raw":
                    block = layout.block_from_bytes(appended, off)
                else:
                    block = layout.block_from_base64(appended[off:].split(b"<", 1)[0])
            else:
                raise _Corrupt(f"unknown data format {fmt!r}")
            if len(block) < count * dtype.itemsize:
                raise _Corrupt(f"expected {count * dtype.itemsize} bytes, got {len(block)}")
            values = np.frombuffer(block, dtype=dtype, count=count)
        if values.size != count:
            raise _Corrupt(f"expected {count} values, found {values.size}")
        sl = tuple(
            slice(ext[2 * i] - whole[2 * i], ext[2 * i] - whole[2 * i] + dims[i]) for i in (2, 1, 0)
        )
        out[sl] = values.reshape(dims[::-1])
    assert out is not None
    ok = len(spacing) == 3 and all(math.isfinite(s) and s > 0 for s in spacing)
    if len(spacing) == 3 and not ok:
        notes.append(f"Ignored the file's invalid spacing {spacing}.")
    return RawArray(out, spacing=spacing if ok else None, notes=notes)  # type: ignore[arg-type]
