"""The batch's reference: the look every volume should take on.

REFERENCE is one of

- a **picture** (PNG, JPEG, ...): the look to match; each volume starts from its own default TF;
- a **TF JSON**: the TF is carried to every volume (:mod:`intuitf.batch.transfer`); its picture
  is the PNG beside it with the same stem (``rank01.tf.json`` → ``rank01.png``, as a run's
  ``best/`` keeps them) or, with ``--reference-volume``, its rendering of that volume. A TF in a
  run's ``best/`` folder counts as that run;
- a **finished run folder** (``intuitf optimize -o RUN``): its best TF and rendering; the run's
  own volume gives the histogram the TF's materials are matched from.

Everything the workers need is saved once under ``DIR/reference/`` (the picture, the TF, the
reference volume's histogram), so no worker reads the reference volume again.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from intuitf.errors import IntuitfError
from intuitf.session.rundir import RunDirectory
from intuitf.tf import GaussianTF

PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".gif", ".webp", ".tif", ".tiff")


@dataclass
class Reference:
    """What the batch aims at: a picture, and possibly the TF and volume it came from."""

    kind: str  # "picture" | "tf" | "run"
    source: str
    picture: np.ndarray
    tf: GaussianTF | None = None
    counts: np.ndarray | None = None  # the reference volume's histogram over [0, 1]
    value_range: tuple[float, float] | None = None
    volume: str | None = None
    notes: list[str] = field(default_factory=list)

    # -- saving for the workers ---------------------------------------------------------
    def save(self, folder: Path) -> None:
        from intuitf.imageio import png_bytes
        from intuitf.session.rundir import atomic_write_bytes, atomic_write_json

        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(folder / "reference.png", png_bytes(self.picture))
        if self.tf is not None:
            atomic_write_bytes(folder / "reference.tf.json", self.tf.to_json().encode())
        atomic_write_json(
            folder / "reference.json",
            {
                "kind": self.kind,
                "source": self.source,
                "volume": self.volume,
                "value_range": list(self.value_range) if self.value_range else None,
                "counts": self.counts.tolist() if self.counts is not None else None,
                "notes": self.notes,
            },
        )

    @classmethod
    def load_saved(cls, folder: Path) -> Reference:
        from intuitf.imageio import load_image
        from intuitf.tf import load_tf

        try:
            meta = json.loads((folder / "reference.json").read_text(encoding="utf-8"))
            picture = load_image(folder / "reference.png")
        except (OSError, json.JSONDecodeError) as exc:
            raise IntuitfError(
                f"The batch's saved reference in {folder} is missing or unreadable ({exc}).",
                "Start the batch again with its REFERENCE.",
            ) from None
        tf_path = folder / "reference.tf.json"
        return cls(
            kind=meta.get("kind", "picture"),
            source=meta.get("source", ""),
            picture=picture,
            tf=load_tf(tf_path) if tf_path.exists() else None,
            counts=np.asarray(meta["counts"], np.float64) if meta.get("counts") else None,
            value_range=tuple(meta["value_range"]) if meta.get("value_range") else None,
            volume=meta.get("volume"),
            notes=list(meta.get("notes", [])),
        )

    def similarity(self, image: np.ndarray) -> float:
        """How close ``image``'s look is to the reference picture: the similarity of the colour
        distributions of their foregrounds (the rendered materials), as the metric judge's
        ``color_style_matching`` measures it: intersection of coarse CIELAB histograms minus
        the distance of the mean colours / 100 (1 = the same colours in the same shares)."""
        return similarity(image, self.picture)

    def describe(self) -> str:
        if self.kind == "picture":
            return f"picture {self.source}"
        what = "TF" if self.kind == "tf" else "run"
        on = f" on {self.volume}" if self.volume else ""
        return f"{what} {self.source}{on}"


def similarity(image: np.ndarray, reference: np.ndarray) -> float:
    """Colour-distribution similarity of ``image`` to ``reference`` (see Reference.similarity)."""
    from intuitf.evaluator.metric import MetricJudge
    from intuitf.evaluator.types import Intent

    intent = Intent(kind="image", reference=np.asarray(reference))
    score = MetricJudge(cache_size=4).score(np.asarray(image), "color_style_matching", intent)
    return float(score) if score is not None else float("nan")


def _volume_counts(spec_volume: dict | str, notes: list[str]):
    """The histogram and value range of a reference volume, or (None, None) with a note."""
    from intuitf.session.spec import VolumeSpec

    try:
        vs = VolumeSpec.model_validate(
            {"source": spec_volume} if isinstance(spec_volume, str) else spec_volume
        )
        vol = vs.load()
    except Exception as exc:  # noqa: BLE001 - any failure: carry by units instead
        msg = getattr(exc, "message", str(exc))
        notes.append(
            f"The reference volume could not be read ({msg}); its TF is carried by data units, "
            "not by materials."
        )
        return None, None, None
    counts, _ = vol.histogram()
    return np.asarray(counts, np.float64), tuple(vol.value_range), vol.name


def _render(tf: GaussianTF, volume_source: str, reader: dict, size: int, camera: dict | None):
    from intuitf.render import Camera, VolumeRenderer
    from intuitf.volume import load_volume

    vol = load_volume(volume_source, **reader)
    cam = Camera.from_dict(camera) if camera else Camera()
    img = VolumeRenderer(vol, size=size).render(tf, cam)
    counts, _ = vol.histogram()
    return img, np.asarray(counts, np.float64), tuple(vol.value_range), vol.name


def _from_run(run: Path, notes: list[str]) -> Reference:
    from intuitf.imageio import load_image
    from intuitf.tf import load_tf

    rd = RunDirectory(run)
    record = rd.read_run()
    tf_path, pic_path = rd.best_file(1, ".tf.json"), rd.best_file(1, ".png")
    if not tf_path.exists() or not pic_path.exists():
        raise IntuitfError(
            f"{run} has no best result yet (best/rank01.tf.json and best/rank01.png).",
            "Finish that run first (intuitf optimize --resume RUN), or give its picture or TF.",
        )
    spec = record.get("spec") or {}
    volume = spec.get("volume") or record.get("volume_source")
    counts = value_range = name = None
    if volume:
        counts, value_range, name = _volume_counts(volume, notes)
    else:
        notes.append("The run does not say which volume it used; its TF is carried by units.")
    tf = load_tf(tf_path)
    return Reference(
        kind="run",
        source=str(run),
        picture=load_image(pic_path),
        tf=tf,
        counts=counts,
        value_range=value_range or tf.value_range,
        volume=name,
        notes=notes,
    )


def load_reference(
    path: str | Path,
    *,
    reference_volume: str | None = None,
    reader: dict | None = None,
    size: int = 512,
    camera: dict | None = None,
) -> Reference:
    """Read REFERENCE (a picture, a TF JSON or a run folder); see the module notes.

    ``reference_volume`` (read with ``reader`` options) is the volume a TF was designed for:
    its histogram places the TF's materials, and it renders the picture when none is beside
    the TF.
    """
    from intuitf.imageio import load_image
    from intuitf.tf import load_tf

    p = Path(path).expanduser()
    notes: list[str] = []
    if not p.exists():
        raise IntuitfError(
            f"The reference {p} does not exist.",
            "Give a picture, a TF JSON, or a finished run folder as REFERENCE.",
        )
    if p.is_dir():
        if not RunDirectory(p).exists():
            raise IntuitfError(
                f"{p} is a folder but not a run folder (no run.json).",
                "Give a picture, a TF JSON, or a folder written by intuitf optimize.",
            )
        ref = _from_run(p, notes)
    elif p.name.lower().endswith(".json"):
        tf = load_tf(p)
        run = p.parent.parent
        stem = p.name[: -len(".tf.json")] if p.name.endswith(".tf.json") else p.stem
        beside = p.with_name(stem + ".png")
        if (
            reference_volume is None
            and RunDirectory(run).exists()
            and p.with_name(stem + ".tf.json") == RunDirectory(run).best_file(1, ".tf.json")
        ):
            return _from_run(run, notes)
        counts = value_range = name = None
        picture = None
        if reference_volume is not None:
            rendered, counts, value_range, name = _render(
                tf, reference_volume, reader or {}, size, camera
            )
            picture = load_image(beside) if beside.exists() else rendered
        elif beside.exists():
            picture = load_image(beside)
            notes.append(
                "No --reference-volume: the TF is carried by data units, not by materials."
            )
        else:
            raise IntuitfError(
                f"The TF {p} comes without a picture of the look it makes.",
                f"Put its rendering beside it as {beside.name}, or give the volume it was "
                "designed for with --reference-volume VOLUME.",
            )
        ref = Reference("tf", str(p), picture, tf, counts, value_range or tf.value_range, name,
                        notes)  # fmt: skip
    elif p.name.lower().endswith(PICTURE_SUFFIXES):
        ref = Reference("picture", str(p), load_image(p), notes=notes)
    else:
        raise IntuitfError(
            f"{p}: not a picture, a TF JSON or a run folder.",
            "Give a PNG/JPEG picture, a *.tf.json, or a folder written by intuitf optimize.",
        )
    return ref
