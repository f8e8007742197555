"""A model names the structures: one request with the structure atlas, names back.

The atlas shows each foreground structure of the map rendered alone, with its descriptors (a
line a person can read and a JSON object a program can), and asks for a short common name per
structure ("pot", "leaves", "enamel", "skull") as JSON: ``{"names": {"S1": "leaves", ...}}``.
The names go into the map (:meth:`StructureMap.named`), where a part word that matches a
name beats any guess from descriptors (:func:`intuitf.intent.parts.match_parts`). It costs
one call per volume; the session keeps the named map with the volume.

This module builds the request and reads the answer (pure); :func:`atlas_images` renders the
pictures and :func:`request_names` sends the request over HTTP to an OpenAI-compatible server.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable

import numpy as np

from intuitf.intent.structures import StructureMap

#: The first words of an atlas request (the fake model server recognises it by them).
ATLAS_MARK = "STRUCTURE ATLAS"

_PROMPT = (
    ATLAS_MARK + ": the volume {name} was split into structures (connected parts of one "
    "material). Each is shown alone below, with what was measured about it. Name each with a "
    "short common noun a person would use for it in this object (for example pot, leaves, "
    "trunk, enamel, dentin, root, skin, bone, skull, vessel, outer part, inner part, "
    "background, noise). Answer as JSON: "
    '{{"names": {{"S1": "...", "S2": "..."}}}}, one entry per structure shown.'
)


def descriptor(s) -> dict:
    """What the atlas tells about one structure, as JSON (rounded)."""
    return {
        "id": f"S{s.id}",
        "values": [round(v, 3) for v in s.value_range],
        "share": round(s.share, 4),
        "centroid": [round(v, 3) for v in s.centroid],
        "bbox": [round(v, 3) for v in s.bbox],
        "position": s.position,
        "outer": s.outer,
        "shape": s.shape,
        "enclosed_by": None if s.enclosed_by is None else f"S{s.enclosed_by}",
    }


def atlas_messages(smap: StructureMap, images: dict[int, np.ndarray], name: str = "") -> list:
    """The chat messages (OpenAI format) of the atlas request: text, then per structure its
    descriptors and its picture (``images``: structure id -> uint8 RGB)."""
    content: list[dict] = [{"type": "text", "text": _PROMPT.format(name=name or "")}]
    for s in smap.foreground():
        content.append({"type": "text", "text": s.describe() + "\n" + json.dumps(descriptor(s))})
        if s.id in images:
            content.append({"type": "image_url", "image_url": {"url": _data_uri(images[s.id])}})
    return [{"role": "user", "content": content}]


def _data_uri(img: np.ndarray) -> str:
    import base64
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img[..., :3], dtype=np.uint8)).save(buf, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def parse_names(text: str, smap: StructureMap | None = None) -> dict[int, str]:
    """Structure names from a model's answer (JSON, possibly in a code fence or with prose).

    Unknown structure ids and empty names are dropped; names are lower-cased and trimmed.
    """
    m = re.search(r"\{.*\}", text or "", re.S)
    if not m:
        return {}
    try:
        data = json.loads(m.group(0))
    except json.JSONDecodeError:
        return {}
    names = data.get("names", data) if isinstance(data, dict) else {}
    known = None if smap is None else {s.id for s in smap.structures}
    out: dict[int, str] = {}
    for k, v in (names or {}).items():
        mk = re.fullmatch(r"\s*S?(\d+)\s*", str(k))
        if not mk or not isinstance(v, str) or not v.strip():
            continue
        sid = int(mk.group(1))
        if known is None or sid in known:
            out[sid] = v.strip().lower()[:60]
    return out


def atlas_images(volume, smap: StructureMap, camera=None, size: int = 160) -> dict[int, np.ndarray]:
    """Each foreground structure rendered alone (its voxels kept, the rest cleared), white on
    black with shading, from ``camera`` (default: the classic view)."""
    from intuitf.render import Camera, VolumeRenderer
    from intuitf.tf import Gaussian, GaussianTF
    from intuitf.volume import Volume

    if smap.labels is None:
        raise ValueError("The structure map has no label grid to render the atlas from.")
    cam = camera or Camera(azimuth=30.0, elevation=20.0)
    data = volume.data
    labels = upsample_labels(smap.labels, data.shape)
    out = {}
    for s in smap.foreground():
        only = np.where(labels == s.id + 1, data, 0.0).astype(np.float32)
        v = Volume(only, volume.spacing, volume.name, value_range=volume.value_range)
        lo, hi = s.value_range
        tf = GaussianTF((Gaussian(float(np.clip((lo + hi) / 2, 0, 1)),
                                  float(np.clip((hi - lo) / 2 + 0.02, 0.005, 0.3)), 0.6,
                                  (0.95, 0.95, 0.95)),))  # fmt: skip
        out[s.id] = VolumeRenderer(v, size=size, shading=True).render(tf, cam)
    return out


def upsample_labels(labels: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Nearest-neighbour labels of the reduced grid on the full grid."""
    idx = [np.minimum((np.arange(n) * labels.shape[k]) // n, labels.shape[k] - 1)
           for k, n in enumerate(shape)]  # fmt: skip
    return labels[np.ix_(*idx)]


def request_names(
    smap: StructureMap,
    images: dict[int, np.ndarray],
    base_url: str,
    model: str = "default",
    api_key: str | None = None,
    name: str = "",
    post: Callable | None = None,
    timeout: float = 120.0,
) -> dict[int, str]:
    """Send the atlas request to an OpenAI-compatible ``base_url`` and read the names.

    One call. ``post`` replaces :func:`httpx.post` (tests). Raises ``RuntimeError`` on an HTTP
    error with the server's message.
    """
    import httpx

    body = {
        "model": model,
        "messages": atlas_messages(smap, images, name),
        "response_format": {"type": "json_object"},
    }
    headers = {"Authorization": f"Bearer {api_key}"} if api_key else {}
    send = post or httpx.post
    r = send(base_url.rstrip("/") + "/chat/completions", json=body, headers=headers,
             timeout=timeout)  # fmt: skip
    if r.status_code >= 400:
        raise RuntimeError(f"Naming the structures failed ({r.status_code}): {r.text[:300]}")
    text = r.json()["choices"][0]["message"]["content"]
    return parse_names(text, smap)


def name_structures(
    volume,
    base_url: str,
    model: str = "default",
    api_key: str | None = None,
    camera=None,
    size: int = 160,
) -> StructureMap:
    """Name ``volume``'s structures with one atlas request; the named map is kept with the
    volume (:func:`intuitf.intent.hints.remember_structure_map`), so words match by names."""
    from intuitf.intent.hints import remember_structure_map, structure_map_of

    smap = structure_map_of(volume)
    images = atlas_images(volume, smap, camera, size)
    names = request_names(smap, images, base_url, model, api_key, name=volume.name)
    named = smap.named(names)
    remember_structure_map(volume, named)
    return named
