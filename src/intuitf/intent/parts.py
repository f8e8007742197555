"""Words that name parts ("pot", "leaves", "crown", "outer part") matched to structures.

Each kind of part is described by what a structure of that kind looks like in the structure map
(:mod:`intuitf.intent.structures`): where it is (bottom, top, inner, outer), its shape (thin,
branching, plate, scattered ...), how dense it is among the object's materials and how much of
the object it makes. :func:`match_parts` scores every structure for every kind the words name
and assigns them jointly, so that two words land on two different materials where the map has
enough (one 1-D transfer function colours values, not places: two parts of one material share a
colour). A structure with a name (from a model or a label atlas) that matches the word wins over
any score.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import permutations

from intuitf.intent.structures import Structure, StructureMap


@dataclass(frozen=True)
class _Ctx:
    """What a score needs to know about the whole map."""

    densities: list[float]  # the foreground materials' centres, by rank
    main: int  # the material with most voxels
    lowest: int  # the lowest foreground material

    def rank(self, s: Structure) -> float:
        """0 for the lowest foreground material .. 1 for the densest."""
        mats = sorted({m for m in self.densities})
        c = s.center
        if len(mats) < 2:
            return 0.5
        i = min(range(len(mats)), key=lambda k: abs(mats[k] - c))
        return i / (len(mats) - 1)


Score = Callable[[Structure, _Ctx], float]


def _pos(s: Structure, want: str) -> float:
    return 1.0 if s.position == want else (0.4 if s.position == "centre" else 0.0)


def _shape(s: Structure, *good: str) -> float:
    return 1.0 if s.shape in good else 0.0


def _container(s, c):
    return (2.0 * (1.0 - s.height) + _shape(s, "plate", "shell", "blob")
            + 0.8 * c.rank(s) + (0.5 if s.outer else 0.0) - 2.0 * _shape(s, "scattered"))  # fmt: skip


def _stem(s, c):
    # A stem stands in the open: the soil in a pot can branch as much (at 64³ the bonsai's
    # soil is one branching piece, larger than the trunk), but the pot encloses it. Wood is
    # denser than the foliage around it (whose faint halo branches too, and is larger).
    return (1.5 * _shape(s, "branching", "thin", "elongated") + 0.5 * (1.0 - abs(s.height - 0.5))
            + 0.5 * min(1.0, 4 * s.share) - 1.0 * _shape(s, "scattered", "plate")
            + (0.5 if s.outer else 0.0) + 0.8 * c.rank(s))  # fmt: skip


def _foliage(s, c):
    return (2.0 * _shape(s, "scattered") + 0.8 * s.height + 0.5 * (1.0 - c.rank(s))
            + 0.5 * _shape(s, "branching", "thin"))  # fmt: skip


def _crown(s, c):
    return 1.5 * c.rank(s) + 1.0 * s.height + (0.3 if s.outer else 0.0)


def _root(s, c):
    return 1.2 * (1.0 - s.height) + 1.0 * min(1.0, 2 * s.share) + 0.5 * (1.0 - c.rank(s))


def _dentin(s, c):
    return 1.5 * min(1.0, 2 * s.share) + 1.0 * (1.0 - abs(c.rank(s) - 0.5))


#: A part under this share of the object cannot be the layer around it (a speck of partial
#: volume with the lowest values would otherwise win "outer" and "skin" on rank alone).
_LAYER_SHARE = 0.05


def _layer(s: Structure) -> float:
    return 0.0 if s.share >= _LAYER_SHARE else -3.0


def _outer(s, c):
    # Size counts as much as density: an outer layer is a large share of the object. At 64³
    # the engine's blurred casing edge (low values, 6 %) outranked its casing (34 %).
    return (2.0 * (1.0 - c.rank(s)) + 2.0 * min(1.0, 2 * s.share) + (0.5 if s.outer else 0.0)
            - (1.0 if s.enclosed_by is not None else 0.0) + _layer(s))  # fmt: skip


def _inner(s, c):
    return (1.5 * c.rank(s) + (1.0 if s.enclosed_by is not None else 0.0)
            + 0.5 * _pos(s, "centre") + 0.5 * min(1.0, 10 * s.share))  # fmt: skip


def _skin(s, c):
    return (2.0 * (1.0 - c.rank(s)) + 1.0 * min(1.0, 2 * s.share) + (0.5 if s.outer else 0.0)
            + _layer(s))  # fmt: skip


def _bone(s, c):
    # Bone is denser than the body around it, never the body itself: the material with most
    # voxels is the soft tissue (at 64³ the head's blurred skin edge, a thin low material, made
    # the soft tissue "not the lowest" and its 81 % won "bone" over the skull).
    return (1.5 * (1.0 if 0.0 < c.rank(s) else 0.0) + 0.8 * min(1.0, 10 * s.share)
            + 0.5 * _shape(s, "thin", "branching", "elongated", "plate") - 0.3 * c.rank(s)
            - 1.0 * (s.material == c.main))  # fmt: skip


def _vessel(s, c):
    return 1.5 * _shape(s, "thin", "branching", "elongated") + 1.0 * (0.0 < c.rank(s) < 1.0)


#: Kinds of parts: the words that name them and how a structure of that kind scores.
PART_KINDS: dict[str, tuple[str, Score]] = {
    "container": (r"pots?|vases?|containers?|bowls?|planters?|base|tray|dish|jars?|cups?", _container),
    "stem": (r"trunks?|branch(es)?|stems?|stalks?|twigs?|wood(en)?|bark", _stem),
    "foliage": (r"leaves|leaf|foliage|canopy|needles|moss|greenery", _foliage),
    "crown": (r"crowns?|enamel|caps?", _crown),
    "root": (r"roots?", _root),
    "dentin": (r"dentine?", _dentin),
    "outer": (r"outer(most)?( parts?| layers?| shell| surface| walls?)?|shells?|casing|"
              r"housing|exterior|outside", _outer),
    "inner": (r"inner(most)?( parts?| structures?| layers?| region| components?)?|"
              r"interior|cores?|inside parts?", _inner),
    "skin": (r"skin|scalp|flesh", _skin),
    "bone": (r"bones?|bony|skeleton|skeletal|skull|cranium|spine|ribs?", _bone),
    "vessel": (r"(blood )?vessels?|arter(y|ies)|veins?|aorta|vasculature", _vessel),
}  # fmt: skip

_KIND_RE = {k: re.compile(rf"\b(?:{p})\b") for k, (p, _) in PART_KINDS.items()}


def kind_of(words: str) -> str | None:
    """The part kind ``words`` name ("the pot" -> "container"), or None."""
    low = words.lower()
    for k, rx in _KIND_RE.items():
        if rx.search(low):
            return k
    return None


def _context(smap: StructureMap) -> _Ctx:
    fg = smap.foreground()
    dens = [s.center for s in fg]
    if not fg:
        return _Ctx([], 0, 0)
    by_mat: dict[int, int] = {}
    for s in fg:
        by_mat[s.material] = by_mat.get(s.material, 0) + s.voxels
    main = max(by_mat, key=lambda m: by_mat[m])
    return _Ctx(dens, main, min(by_mat))


def match_parts(kinds: Sequence[str], smap: StructureMap) -> dict[str, Structure]:
    """The structure each part kind names (kinds without a candidate are left out).

    A structure named (by a model or a label atlas) with a word of that kind wins. The others
    are assigned jointly: the assignment with the largest total score, where two kinds share a
    material only when the map has fewer foreground materials than kinds.
    """
    fg = smap.foreground()
    if not fg or not kinds:
        return {}
    out: dict[str, Structure] = {}
    todo = []
    for k in dict.fromkeys(kinds):
        named = [s for s in fg if s.name and kind_of(s.name) == k]
        if named:
            out[k] = max(named, key=lambda s: s.voxels)
        elif k in PART_KINDS:
            todo.append(k)
    if not todo:
        return out
    ctx = _context(smap)
    scores = {k: [PART_KINDS[k][1](s, ctx) for s in fg] for k in todo}
    n_mats = len({s.material for s in fg})
    taken = {s.material for s in out.values()}
    best, best_total = None, -1e9
    cand = range(len(fg))
    # The map has a handful of structures and the words name a few parts: try them all.
    if len(todo) <= len(fg) and len(fg) ** len(todo) <= 50000:
        for pick in permutations(cand, len(todo)):
            mats = [fg[i].material for i in pick]
            clash = len(mats) - len(set(mats)) + len(taken.intersection(mats))
            total = sum(scores[k][i] for k, i in zip(todo, pick, strict=True))
            if clash and n_mats >= len(todo) + len(taken):
                total -= 3.0 * clash
            if total > best_total:
                best, best_total = pick, total
    if best is None:  # more kinds than structures: each kind its best structure
        best = tuple(max(cand, key=lambda i, k=k: scores[k][i]) for k in todo)
    for k, i in zip(todo, best, strict=True):
        out[k] = fg[i]
    return out
