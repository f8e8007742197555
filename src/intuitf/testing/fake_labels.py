"""The fake model server's answer to a structure-atlas request, from label volumes.

A :class:`LabelNamer` knows a volume's labels (an integer array the size of the volume, 0 for
none) and the name of each label. Asked to name the structures of an atlas
(:mod:`intuitf.intent.atlas`), it reads each structure's descriptors from the request (its
bounding box and value range), finds the label most of the volume's voxels with those values
in that box carry, and answers its name; with ``error_rate`` it answers another label's name
instead (a model that is sometimes wrong). Deterministic for a seed.
"""

from __future__ import annotations

import json
import random
import re

import numpy as np

from intuitf.intent.atlas import ATLAS_MARK


def is_atlas_request(body: dict) -> bool:
    """Whether a chat request is a structure-atlas request."""
    for msg in body.get("messages", []):
        content = msg.get("content")
        parts = [content] if isinstance(content, str) else content or []
        for part in parts:
            text = part if isinstance(part, str) else part.get("text", "")
            if isinstance(text, str) and text.startswith(ATLAS_MARK):
                return True
    return False


def atlas_descriptors(body: dict) -> list[dict]:
    """The JSON descriptors of each structure in an atlas request, in order."""
    out = []
    for msg in body.get("messages", []):
        content = msg.get("content")
        for part in content if isinstance(content, list) else []:
            text = part.get("text", "") if isinstance(part, dict) else ""
            for line in str(text).splitlines():
                line = line.strip()
                if line.startswith("{") and '"id"' in line:
                    try:
                        out.append(json.loads(line))
                    except json.JSONDecodeError:
                        continue
    return out


class LabelNamer:
    """Names atlas structures from a label volume (see the module docstring)."""

    def __init__(
        self,
        data: np.ndarray,
        labels: np.ndarray,
        names: dict[int, str],
        error_rate: float = 0.1,
        seed: int = 0,
    ) -> None:
        if np.shape(data) != np.shape(labels):
            raise ValueError(f"labels {np.shape(labels)} differ from the volume {np.shape(data)}")
        if not 0.0 <= error_rate <= 1.0:
            raise ValueError(f"error_rate must be within [0, 1], got {error_rate}")
        self.data = np.asarray(data)
        self.labels = np.asarray(labels)
        self.names = dict(names)
        self.error_rate = float(error_rate)
        self.rng = random.Random(seed)

    def name_of(self, desc: dict) -> str:
        """The name of the label the structure described by ``desc`` mostly covers."""
        z, y, x = self.data.shape
        x0, y0, z0, x1, y1, z1 = (float(v) for v in desc.get("bbox", (0, 0, 0, 1, 1, 1)))
        lo, hi = (float(v) for v in desc.get("values", (0.0, 1.0)))
        sl = (slice(int(z0 * (z - 1)), int(np.ceil(z1 * (z - 1))) + 1),
              slice(int(y0 * (y - 1)), int(np.ceil(y1 * (y - 1))) + 1),
              slice(int(x0 * (x - 1)), int(np.ceil(x1 * (x - 1))) + 1))  # fmt: skip
        d, lab = self.data[sl], self.labels[sl]
        hit = lab[(d >= lo) & (d <= hi)]
        counts = np.bincount(hit.ravel().astype(np.int64), minlength=1)
        counts[0] = 0  # unlabelled voxels name nothing
        true = int(np.argmax(counts)) if counts.sum() else 0
        name = self.names.get(true, "background")
        if self.rng.random() < self.error_rate:
            others = sorted({n for n in self.names.values() if n != name} | {"background"} - {name})
            name = self.rng.choice(others)
        return name

    def answer(self, body: dict) -> str:
        """The JSON answer to an atlas request."""
        names = {}
        for desc in atlas_descriptors(body):
            if re.fullmatch(r"S\d+", str(desc.get("id", ""))):
                names[desc["id"]] = self.name_of(desc)
        return json.dumps({"names": names})
