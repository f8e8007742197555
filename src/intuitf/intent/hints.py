"""Text → material hints: which clause names which material, its colour and its opacity.

"Opaque ivory bone, faint red skin" names two materials, their colours and their opacities,
and general knowledge of CT says where each sits among the volume's values: air < fat < skin
and soft tissue < muscle < contrast-filled vessels < bone < dentin < enamel < metal. This module
turns a text into such hints and places each on the volume's histogram materials (the peaks
and tail quantiles of :func:`intuitf.tf.defaults.find_materials`):

- **Hounsfield units**, when the volume is CT in HU (values reach about -1000, air): each
  material at its HU range (bone 300-1900, fat -150 to -50, ...);
- otherwise by **role and density order**: soft tissue on the main low material, skin on
  the body's surface (the values between the background and it), bone on the first
  material clearly above it, enamel, teeth and metal on the highest, dentin
  below enamel; "the engine block", "the body", "the object" on the material most voxels
  hold; "dense parts" on the first material above that; "core", "inner", "densest" on the
  highest; "outline", "surface", "outer", "shell" on the boundary between the background and
  the first material. Hints are then kept in density order (a denser material never sits
  below a lighter one). On a histogram peak a hint sits one spread below it, 1.5 spreads
  wide: a material is seen where its surface is, on the flank toward what surrounds it.

It says plainly which words it does not understand (:attr:`TextHints.unknown`); a word it
does not know changes nothing. The Explorer gets the hints as plain numbers
(:func:`explorer_hints`): it never sees the text, and the judge still decides.

An edit ("make the crown gold", applied to selected features) gives hints without a place:
the selection says where, so the colour and opacity apply to the selected Gaussians.
"""

from __future__ import annotations

import re
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from intuitf.evaluator.types import Intent
from intuitf.intent.colours import NAMED_COLOURS, named_colours
from intuitf.intent.parts import PART_KINDS, kind_of, match_parts
from intuitf.intent.structures import StructureMap

RGB = tuple[float, float, float]

# -- vocabulary --------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Term:
    material: str  # canonical name
    pattern: str  # regular expression (matched on lower-case text, at word boundaries)
    level: float  # place in the density order (CT): air 0 ... metal 8
    role: str  # how it is placed without Hounsfield units (see _place_by_role)
    hu: tuple[float, float] | None = None  # Hounsfield range, for CT in HU


#: Materials by the words that name them. Longer phrases come first (matched first). Parts
#: (role "part": a pot, the leaves, the crown ...) are placed on the structure the words name
#: (:mod:`intuitf.intent.parts`); they come first, so at one place they win over a material.
TERMS: tuple[_Term, ...] = (
    _Term("pot", PART_KINDS["container"][0], 3.0, "part"),
    _Term("branch", PART_KINDS["stem"][0], 3.0, "part"),
    _Term("leaves", PART_KINDS["foliage"][0], 3.0, "part"),
    _Term("crown", r"crowns?", 6.5, "part"),
    _Term("root", PART_KINDS["root"][0], 5.5, "part"),
    _Term("outer part", r"outer(most)? (parts?|layers?|walls?)|casing|housing", 1.0, "part"),
    _Term("inner part", r"inner(most)? (parts?|structures?|components?)|interior parts?", 7.0,
          "part"),
    _Term("soft tissue", r"soft[- ]tissues?", 2.3, "soft", (20, 80)),
    _Term("white matter", r"white matter", 2.4, "soft", (20, 40)),
    _Term("grey matter", r"gr[ae]y matter", 2.3, "soft", (30, 45)),
    _Term("dense parts", r"(dense|denser|high[- ]density|heavy|thick)\s+(parts?|regions?|"
          r"structures?|material|metal|components?|areas?)", 6.0, "dense"),
    _Term("densest parts", r"dense[s]?t(\s+(parts?|regions?|structures?|material))?|"
          r"highest values?|high values?|maxim(a|um)|peaks?", 7.0, "top"),
    _Term("low values", r"low(est)? values?|low[- ]density|light(er)? (parts?|material)|"
          r"thin (parts?|material)", 1.0, "low"),
    _Term("main material", r"(engine )?block|engine|body|object|main (material|structure|part)|"
          r"casing|housing|bulk|matrix|whole (thing|object|volume)|structure", 3.0, "main"),
    _Term("core", r"core|inner(most)?( parts?| structures?| layers?| region)?|interior|"
          r"cent(er|re)|nucleus", 7.0, "top"),
    _Term("outline", r"outlines?|contours?|silhouettes?|surfaces?|shells?|envelopes?|"
          r"outer(most)?( parts?| layers?| shell| surface)?|outside|exterior|boundary|"
          r"boundaries|edges?", 1.0, "boundary"),
    _Term("middle", r"middle|intermediate|medium( values?| density)?|mid[- ]range",
          4.0, "middle"),
    _Term("air", r"air(ways?)?|trachea|sinus(es)?|gas|empty space", 0.0, "air", (-1024, -900)),
    _Term("lungs", r"lungs?|pulmonary", 0.5, "low", (-900, -500)),
    _Term("fat", r"fat|fatty tissue|adipose", 1.0, "soft", (-150, -50)),
    _Term("fluid", r"fluids?|water|csf|cerebrospinal fluid|ventricles?|edema|oedema|cysts?",
          1.5, "soft", (-10, 20)),
    _Term("skin", r"skin|scalp|flesh", 2.0, "skin", (-100, 60)),
    _Term("soft tissue", r"tissues?|organs?|brain|liver|kidneys?|heart|gums?|pulp|"
          r"ligaments?|tendons?", 2.3, "soft", (20, 80)),
    _Term("muscle", r"muscles?|muscular", 2.5, "soft", (35, 60)),
    _Term("cartilage", r"cartilage|discs?|menisc(us|i)", 3.0, "soft", (80, 140)),
    _Term("vessels", r"(blood )?vessels?|arter(y|ies)|veins?|aorta|aneurysms?|blood|"
          r"vasculature|contrast", 3.5, "vessels", (150, 450)),
    _Term("bone", r"bones?|bony|skeleton|skeletal|skull|cranium|spine|vertebra[e]?|ribs?|"
          r"pelvis|femur|jaw|mandible|cortical|trabecular|fins? rays?|fishbones?", 5.0, "bone",
          (300, 1900)),
    _Term("dentin", r"dentine?|roots?", 5.5, "dentin", (1200, 2000)),
    _Term("enamel", r"enamel|crowns?|teeth|tooth|dental", 6.5, "top", (2000, 3000)),
    _Term("metal", r"metal(lic)?|implants?|fillings?|screws?|plates?|stents?|wires?|"
          r"prosthes[ie]s", 8.0, "top", (2500, 4000)),
)  # fmt: skip

_TERM_RE = [(t, re.compile(rf"\b(?:{t.pattern})\b")) for t in TERMS]

#: Opacity words, most specific first: (look, regular expression).
_OPACITY: tuple[tuple[str, re.Pattern], ...] = (
    ("hidden", re.compile(r"\b(hid(e|den)|invisible|remove[d]?|no|without|omit\w*|"
                          r"not (shown|visible))\b")),
    ("semi", re.compile(r"\b(semi[- ]?(op\w*|transparent|translucent)|translucent|"
                        r"half[- ]?transparent|see[- ]through|partly transparent)\b")),
    ("faint", re.compile(r"\b(faint\w*|transparent|ghost\w*|subtle|wispy|barely visible|"
                         r"thin veil|hint of|light(ly)? (veil|touch))\b")),
    ("opaque", re.compile(r"\b((fully?[- ]?)?op[aq]\w*e|solid|dense(ly)? (coloured|colored)|"
                          r"strong|prominent|bold)\b")),
)  # fmt: skip

#: Comparative opacity words of an edit ("make it more transparent").
_MORE_OPAQUE = re.compile(r"\b(more (opaque|solid|visible)|less (transparent|faint)|"
                          r"(solid|opaque|visible)r?|stronger|thicker)\b")  # fmt: skip
_LESS_OPAQUE = re.compile(r"\b(more (transparent|translucent|faint)|less (opaque|solid|visible)|"
                          r"fainter|lighter|thinner|weaker|transparent|translucent|faint)\b")  # fmt: skip

#: Gaussian heights (opacity per unit length) for each look (None: hidden, height 0). A
#: material that fills space gathers opacity along a long path; a surface (the boundary
#: between the background and the body: skin, an outline) is a thin layer of partial-volume
#: values and needs more to show at all.
HEIGHT_BANDS: dict[str | None, tuple[float, float] | None] = {
    "opaque": (0.3, 1.0),
    "semi": (0.01, 0.12),
    "faint": (0.003, 0.04),
    "hidden": None,
    None: (0.02, 0.7),  # named but no opacity word: visible
}
SURFACE_BANDS: dict[str | None, tuple[float, float] | None] = {
    "opaque": (0.4, 1.0),
    "semi": (0.08, 0.4),
    "faint": (0.03, 0.15),
    "hidden": None,
    None: (0.05, 0.8),
}

#: Words that carry no material, colour or opacity but are understood (or harmless).
_KNOWN_WORDS = set(
    """a an the and or with without in on of for to at by from as its it this that these those
    is are be being been make makes made making show shows shown showing render rendered
    rendering renderings display displayed visualise visualize visualised visualized highlight
    highlighted emphasise emphasize emphasised emphasized keep kept leave let want would like
    please i we me my our you your colour color coloured colored colours colors tint tinted
    tinge hue shade shaded shading look looks looking appear appears visible clearly clear
    clean cleanly nice nicely well good very slightly bit little more less most least than
    but while whereas also too only just all every each some other rest else everything
    nothing part parts region regions structure structures layer layers area areas
    volume data scan ct mri image picture view human ray rays value values density
    painted paint in into over under around behind front back against background instead
    same whole change changed turn turned set should can could must so then there here
    inside within through beneath underneath between among above below near
    where which what see seen one two three both either neither like style tone toned
    bright brighter dark darker light pale deep vivid rich soft strong
    object thing model specimen sample tree plant potted""".split()
)

_WORD_RE = re.compile(r"[a-z][a-z'-]*")
_CLAUSE_SPLIT = re.compile(r"[,;.:!?]|\band\b|\bwith\b|\bbut\b|\bwhile\b|\bwhereas\b|\bplus\b")


#: A material peak's hint sits this many of its spreads below the peak (on its lower flank,
#: where its surface is) and is this many times its spread wide.
FLANK = 1.0
FLANK_WIDTH = 1.5

# -- hints -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MaterialHint:
    """One material a text names, with the colour and look it asks for, and where it sits.

    ``center``/``spread`` are normalised values (None when not placed: an edit, or no volume
    given); ``placed_by`` says how the place was found ("hounsfield", "role", "selection").
    ``opacity`` is "opaque", "semi", "faint", "hidden" or None (not said).
    """

    clause: str
    material: str
    words: str
    colour: str | None = None
    rgb: RGB | None = None
    opacity: str | None = None
    level: float = 0.0
    role: str = "soft"
    center: float | None = None
    spread: float = 0.03
    placed_by: str = ""
    structure: int | None = None  # the structure it was placed on (a part word)
    direction: str | None = None  # an edit's direction (see :func:`edit_direction`)
    thin: bool = False  # that structure is thin, plate-like or scattered: it needs more opacity
    #: The values of the structure it was placed on (low, high), normalised.
    reach: tuple[float, float] | None = None

    @property
    def height_band(self) -> tuple[float, float] | None:
        """The Gaussian heights the look asks for (None: hidden, height 0)."""
        surface = self.role in ("boundary", "skin") or self.thin
        bands = SURFACE_BANDS if surface else HEIGHT_BANDS
        return bands.get(self.opacity, bands[None])

    def to_explorer(self) -> dict:
        """The hint as the Explorer takes it (:class:`intuitf.explorer.hints.Hint`)."""
        band = self.height_band
        return {
            "name": self.material,
            "center": self.center,
            "spread": self.spread,
            "color": list(self.rgb) if self.rgb else None,
            "height": list(band) if band else None,
            "hidden": self.opacity == "hidden",
            "direction": self.direction,
            # An edit that names no colour keeps the selected features' colours.
            "keep_color": self.placed_by == "selection" and self.rgb is None,
            "reach": list(self.reach) if self.reach else None,
        }

    def describe(self, value_range: tuple[float, float] | None = None) -> str:
        """One line: '"ivory bone": bone, ivory, opaque, at 205 (role)'."""
        parts = [self.material]
        if self.colour:
            parts.append(self.colour)
        if self.opacity:
            parts.append(self.opacity)
        where = ""
        if self.center is not None:
            v = self.center
            if value_range is not None:
                lo, hi = value_range
                v = lo + v * (hi - lo)
            where = f", at {v:.4g} ({self.placed_by})"
            if self.structure is not None:
                where += f" on S{self.structure}"
        return f'"{self.words}": ' + ", ".join(parts) + where


@dataclass
class TextHints:
    """Everything a text says about single materials, and what it did not understand."""

    text: str
    hints: list[MaterialHint] = field(default_factory=list)
    unknown: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def summary(self, value_range: tuple[float, float] | None = None) -> str:
        """Several lines a person can read: one per hint, then what was not understood."""
        lines = [h.describe(value_range) for h in self.hints] or ["no material named"]
        lines += self.notes
        if self.unknown:
            lines.append("not understood: " + ", ".join(self.unknown))
        return "\n".join(lines)


def parse_text(text: str | None) -> TextHints:
    """The material hints of ``text`` (not yet placed on a volume), and the words not understood.

    Clauses are split at punctuation and at "and", "with", "but", "while"; in each clause the
    first material word names the material, and the clause's colour and opacity words apply to
    it. A clause with a colour or opacity but no material word gives its colour to the
    clause's nearest material (or, with no material in the text at all, is left to the
    palette). Materials named with neither colour nor opacity are kept only when no clause
    says anything else (then "show the bone" means: the bone, visible).
    """
    raw = (text or "").strip()
    out = TextHints(text=raw)
    low = raw.lower()
    used: list[tuple[int, int]] = []
    hints: list[MaterialHint] = []
    for clause in _CLAUSE_SPLIT.split(low):
        clause = clause.strip()
        for term, words, segment in _materials_in(clause):
            colours = named_colours(segment)
            colour = colours[0] if colours else None
            look = _look(segment)
            same = [k for k, h in enumerate(hints) if h.material == term.material]
            if same and (hints[same[0]].colour or hints[same[0]].opacity or not (colour or look)):
                continue  # named twice: the first mention that says something about it wins
            rgb = tuple(float(c) / 255.0 for c in NAMED_COLOURS[colour]) if colour else None
            hint = MaterialHint(
                clause=clause, material=term.material, words=words, colour=colour,
                rgb=rgb, opacity=look, level=term.level, role=term.role,  # type: ignore[arg-type]
            )  # fmt: skip
            if same:
                hints[same[0]] = hint
            else:
                hints.append(hint)
    if any(h.colour or h.opacity for h in hints):
        subject = [h for h in hints if not (h.colour or h.opacity)]
        if subject:
            out.notes.append(
                "named without a colour or opacity, taken as what the volume shows: "
                + ", ".join(f'"{h.words}"' for h in subject)
            )
        hints = [h for h in hints if h.colour or h.opacity]
    out.hints = hints
    out.unknown = _unknown_words(low, used)
    return out


def _materials_in(clause: str) -> list[tuple[_Term, str, str]]:
    """The materials a clause names, each with the words that describe it.

    Matches may not overlap (at one place the longer phrase wins: "soft tissue" over
    "tissue"). A material is described by the words before it, back to the previous
    material ("white bones inside translucent pink soft tissue": "white" for the bones,
    "inside translucent pink" for the soft tissue); the last one also by the words after
    it ("the bones in gold").
    """
    found: list[tuple[int, int, _Term]] = []
    for term, rx in _TERM_RE:
        for m in rx.finditer(clause):
            found.append((m.start(), m.end(), term))
    found.sort(key=lambda f: (f[0], -(f[1] - f[0])))
    kept: list[tuple[int, int, _Term]] = []
    for f in found:
        if not kept or f[0] >= kept[-1][1]:
            kept.append(f)
    out = []
    for k, (a, b, term) in enumerate(kept):
        prev_end = kept[k - 1][1] if k else 0
        before = clause[prev_end:b]
        after = clause[b:] if k == len(kept) - 1 else ""
        segment = before if (named_colours(before) and _look(before)) else before + " " + after
        if k < len(kept) - 1:
            segment = before
        out.append((term, clause[a:b], segment))
    return out


def _look(clause: str) -> str | None:
    """The clause's opacity word: "hidden", "semi", "faint", "opaque" or None."""
    for look, rx in _OPACITY:
        if rx.search(clause):
            return look
    return None


def _unknown_words(text: str, used: list[tuple[int, int]]) -> list[str]:
    """Words of ``text`` that are neither vocabulary, colour, opacity nor common words."""
    covered = np.zeros(len(text) + 1, bool)
    for _, rx in _TERM_RE:
        for m in rx.finditer(text):
            covered[m.start() : m.end()] = True
    for rx in [r for _, r in _OPACITY] + [_MORE_OPAQUE, _LESS_OPAQUE]:
        for m in rx.finditer(text):
            covered[m.start() : m.end()] = True
    colour_rx = re.compile(
        r"\b("
        + "|".join(re.escape(k) for k in sorted(NAMED_COLOURS, key=len, reverse=True))
        + r")\b"
    )
    for m in colour_rx.finditer(text):
        covered[m.start() : m.end()] = True
    out: list[str] = []
    for m in _WORD_RE.finditer(text):
        w = m.group(0).strip("'-")
        if not w or covered[m.start() : m.end()].any() or w in _KNOWN_WORDS:
            continue
        if w.endswith("s") and w[:-1] in _KNOWN_WORDS:
            continue
        if w not in out:
            out.append(w)
    return out


# -- placing hints on a volume -----------------------------------------------------------------


def is_hounsfield(value_range: tuple[float, float], dtype: str | None = None) -> bool:
    """Whether values look like CT in Hounsfield units: air near -1000, bone above +300."""
    lo, hi = value_range
    return lo <= -900.0 and hi >= 300.0 and (dtype is None or not str(dtype).startswith("uint"))


def place_hints(
    parsed: TextHints,
    counts: np.ndarray,
    value_range: tuple[float, float] = (0.0, 1.0),
    dtype: str | None = None,
    structures: StructureMap | None = None,
) -> TextHints:
    """``parsed`` with every hint placed on the volume whose histogram is ``counts``.

    Words naming parts (pot, leaves, crown, outer part ...) go to the structure of
    ``structures`` they name (:func:`intuitf.intent.parts.match_parts`): the hint sits on
    that structure's values. Without a structure map they are placed by role like materials.
    CT in Hounsfield units (:func:`is_hounsfield`): each material at its HU range. Otherwise
    by role among the histogram's materials (see the module docstring), then in density
    order.
    """
    from intuitf.tf.defaults import find_materials

    c = np.asarray(counts, dtype=np.float64).ravel()
    if not parsed.hints or c.size < 8 or c.sum() <= 0:
        return parsed
    lo, hi = (float(v) for v in value_range)
    span = max(hi - lo, 1e-12)
    hu = is_hounsfield((lo, hi), dtype)
    mats = find_materials(c, max_materials=6)
    layout = _Layout.of(c, mats)
    placed: list[MaterialHint] = []
    parts: dict = {}

    def by_structure(h: MaterialHint) -> bool:
        # Parts, and bone outside Hounsfield units (its values vary from scan to scan, its
        # shape and place among the materials do not).
        return h.role == "part" or (h.material == "bone" and not hu)

    if structures is not None:
        kinds = [kind_of(h.words) for h in parsed.hints if by_structure(h)]
        parts = match_parts([k for k in kinds if k], structures)
    for h in parsed.hints:
        kind = kind_of(h.words) if by_structure(h) else None
        if kind is not None and kind in parts and structures is not None:
            st = parts[kind]
            a, b = st.value_range
            if kind == "inner":
                # "The inner part" is everything denser than the object's bulk around it.
                fg = structures.foreground()
                vox: dict[int, int] = {}
                for x in fg:
                    vox[x.material] = vox.get(x.material, 0) + x.voxels
                bulk = max(vox, key=lambda m: vox[m])
                denser = [x for x in fg if x.material > bulk] or [st]
                a = min(x.value_range[0] for x in denser)
                b = max(x.value_range[1] for x in denser)
            # Seen where its surface is: the lower part of its values, where it meets what
            # surrounds it, and wide enough to hold the rest of them.
            center = a + 0.35 * (b - a)
            spread = max(0.012, (b - a) / 4.0)
            if not st.background and center > layout.cutoff:
                # Its tail stays off the background's values, as a material's does: a faint
                # outer layer's tail over the air is a fog over the whole box.
                spread = min(spread, max(0.004, (center - layout.cutoff) / 2.5))
            thin = st.shape in ("thin", "branching", "scattered", "plate")
            placed.append(_with(h, center=float(center), spread=float(spread),
                                placed_by="structure", structure=st.id, thin=thin,
                                reach=(float(a), float(b))))  # fmt: skip
            continue
        role = _PART_ROLE.get(kind_of(h.words) or "", h.role) if h.role == "part" else h.role
        term_hu = next((t.hu for t in TERMS if t.material == h.material and t.hu), None)
        if hu and term_hu is not None:
            a, b = (float(np.clip((v - lo) / span, 0.0, 1.0)) for v in term_hu)
            center, spread, how = (a + b) / 2.0, max(0.004, (b - a) / 4.0), "hounsfield"
            if h.material == "bone":  # what shows bone is its surface, near the lower end
                center = a + 0.25 * (b - a)
        else:
            center, spread = layout.place(role)
            how = "density order" if role not in ("main", "boundary") else role
        placed.append(_with(h, center=float(center), spread=float(spread), placed_by=how))
    if not hu:
        placed = _keep_density_order(placed, layout)
    if structures is not None:
        placed = [_reaching_its_structure(h, structures, placed) for h in placed]
    return TextHints(parsed.text, placed, list(parsed.unknown), list(parsed.notes))


def _reaching_its_structure(
    h: MaterialHint, structures: StructureMap, placed: Sequence[MaterialHint]
) -> MaterialHint:
    """``h``, skin placed by role on a body's edge, reaching the values of the body's main
    structure it lies on, up to the next named material's values.

    The chest's "faint red skin" sits at its body's edge (0.04) and the body's soft tissue
    (0.08, 45 % of the voxels) was a material nobody named: in any colour, often ivory, it
    turned the faint red body white behind the ribs.
    """
    if h.center is None or h.reach is not None or h.role != "skin":
        return h
    fg = [s for s in structures.foreground() if s.value_range[0] <= h.center <= s.value_range[1]]
    if not fg:
        return h
    body = max(fg, key=lambda s: s.share)
    hi = body.value_range[1]
    for o in placed:
        if o is not h and o.center is not None and o.center > h.center:
            hi = min(hi, o.reach[0] if o.reach else o.center - 2.5 * o.spread)
    if hi <= h.center:
        return h
    return _with(h, reach=(float(h.center), float(hi)))


#: Without a structure map, a part is placed like the material it usually is.
_PART_ROLE = {
    "container": "top", "stem": "main", "foliage": "low", "crown": "top", "root": "dentin",
    "dentin": "dentin", "outer": "boundary", "inner": "top", "skin": "skin", "bone": "bone",
    "vessel": "vessels",
}  # fmt: skip


def _with(h: MaterialHint, **kw) -> MaterialHint:
    d = dict(h.__dict__)
    d.update(kw)
    return MaterialHint(**d)


@dataclass
class _Layout:
    """Where a volume's materials are: background mode, main material, the rest, sorted."""

    background: float
    slots: list[tuple[float, float, float]]  # (center, spread, fraction), by value
    main: int
    cutoff: float = 0.0

    @classmethod
    def of(cls, counts: np.ndarray, mats) -> _Layout:
        from intuitf.tf.defaults import background_cutoff

        n = counts.size
        cut = background_cutoff(counts)
        below = counts[: max(1, int(cut * (n - 1)) + 1)]
        background = (int(np.argmax(below)) + 0.5) / n
        slots = [(float(m.center), float(m.spread), float(m.fraction)) for m in mats]
        if not slots:
            slots = [(0.5, 0.05, 1.0)]
        main = int(np.argmax([s[2] for s in slots]))
        return cls(background, slots, main, float(cut))

    @property
    def first_real(self) -> float:
        """The first material that holds a twentieth of the voxels (not a shoulder of the
        background's noise), else the main one."""
        for c, _, frac in self.slots:
            if frac >= 0.05:
                return c
        return self.slots[self.main][0]

    @property
    def boundary(self) -> float:
        """Where the background meets the body: the partial-volume values of its surface.

        Halfway between the background's mode and the first real material, but clear of the
        background's own tail (at least 15 % of the way from the histogram's valley).
        """
        first = self.first_real
        return max((self.background + first) / 2.0, self.cutoff + 0.15 * (first - self.cutoff))

    @property
    def boundary_spread(self) -> float:
        """Narrow enough that the Gaussian's tail stays off the background (a faint tail
        over the many background voxels is a veil over the whole box)."""
        b = self.boundary
        return max(0.008, min((self.first_real - b) / 3.0, (b - self.background) / 4.0))

    def _peaks_above(self, value: float, gap: float) -> list[int]:
        """Materials above ``value + gap``: the histogram's peaks there, else its quantiles."""
        above = [i for i, s in enumerate(self.slots) if s[0] > value + gap]
        peaks = [i for i in above if self.slots[i][2] > 0.0]
        return peaks or above

    def place(self, role: str) -> tuple[float, float]:
        s, main = self.slots, self.main
        top = len(s) - 1
        if role == "air":
            return self.background, 0.02
        if role == "boundary":
            return self.boundary, self.boundary_spread
        if role in ("main", "soft"):
            i = main
        elif role == "skin":
            # What shows skin in a rendering is the body's surface: the partial-volume
            # values between the background and the body (the tissue itself fills space).
            return self.boundary, self.boundary_spread
        elif role == "low":
            i = 0 if s[0][2] >= 0.05 else min(1, top)
        elif role == "middle":
            i = len(s) // 2
        elif role in ("bone", "dense", "vessels"):
            above = self._peaks_above(s[main][0], 0.08)
            i = above[0] if above else top
            if role == "vessels" and above and i > main + 1:
                i = main + 1
        elif role == "dentin":
            i = max(main, top - 1) if top > 0 else 0
        elif role == "top":
            # The extreme end of the range is a handful of voxels: the material below it.
            i = top - 1 if s[top][0] > 0.985 and top > 0 else top
        else:
            i = main
        c, spread, frac = s[int(i)]
        if frac > 0.0:
            # A material is seen where its surface is: on the lower flank of its peak, where
            # it meets what lies around it (a Gaussian there shows the surface and, wider,
            # the material behind it).
            c -= FLANK * spread
            spread *= FLANK_WIDTH
        return c, max(spread, 0.012)

    def slot_of(self, center: float) -> int:
        return int(np.argmin([abs(center - s[0]) for s in self.slots]))


def _keep_density_order(hints: list[MaterialHint], layout: _Layout) -> list[MaterialHint]:
    """Re-place the density-ordered hints so that a denser material never sits below a lighter one.

    Each hint keeps its place when the order allows; otherwise the assignment of materials
    (the boundary just above the background counts as the lowest) that moves the hints the
    fewest steps from their places wins, sharing a material only when there is no other way.
    """
    slots = [(layout.boundary, layout.boundary_spread)] + [(c, sp) for c, sp, _ in layout.slots]
    todo = sorted(
        (k for k, h in enumerate(hints) if h.placed_by == "density order"),
        key=lambda k: hints[k].level,
    )
    if len(todo) < 2:
        return hints
    want = [int(np.argmin([abs(hints[k].center - c) for c, _ in slots])) for k in todo]  # type: ignore[operator]
    n, m = len(todo), len(slots)
    inf = float("inf")
    cost = np.full((n, m), inf)
    back = np.zeros((n, m), int)
    cost[0] = [abs(j - want[0]) for j in range(m)]
    for i in range(1, n):
        differ = hints[todo[i]].level - hints[todo[i - 1]].level >= 0.5
        for j in range(m):
            options = [
                cost[i - 1, jj] + (1.5 if differ and jj == j else 0.0) for jj in range(j + 1)
            ]
            jj = int(np.argmin(options))
            cost[i, j] = options[jj] + abs(j - want[i])
            back[i, j] = jj
    j = int(np.argmin(cost[-1]))
    out = list(hints)
    for i in range(n - 1, -1, -1):
        if j != want[i]:
            c, sp = slots[j]
            out[todo[i]] = _with(hints[todo[i]], center=float(c), spread=float(max(sp, 0.012)))
        j = back[i, j]
    return out


# -- for the Session ---------------------------------------------------------------------------


_HIDE_RE = re.compile(r"\b(hide|hidden|invisible|remove[d]?|not (shown|visible)|get rid of)\b")
_BRIGHTER_RE = re.compile(r"\b(brighter|brighten|lighten|lighter colou?r|more vivid|vivid)\b")
_DARKER_RE = re.compile(r"\b(darker|darken|dimmer|deeper colou?r)\b")


def edit_direction(text: str | None) -> str | None:
    """What an edit asks of its selection's look: "hidden", "brighter", "darker", "fainter",
    "stronger", or None (only a colour, or nothing checkable)."""
    low = (text or "").lower()
    if _HIDE_RE.search(low):
        return "hidden"
    if _BRIGHTER_RE.search(low):
        return "brighter"
    if _DARKER_RE.search(low):
        return "darker"
    look = _look(low)
    if _LESS_OPAQUE.search(low) or look in ("faint", "semi"):
        return "fainter"
    if _MORE_OPAQUE.search(low) or look == "opaque":
        return "stronger"
    return None


def intent_hints(intent: Intent, volume=None, structures: StructureMap | None = None) -> TextHints:
    """The hints of an intent's text, placed on ``volume`` when given (not for an edit).

    ``structures`` is the volume's structure map; by default it is built from the volume
    (:func:`structure_map_of`, kept for the volume's lifetime) when the text names parts.
    """
    parsed = parse_text(intent.text)
    if intent.kind == "edit":
        # The selection says where: every hint applies to the selected features.
        direction = edit_direction(intent.text)
        parsed.hints = [
            _with(h, center=None, placed_by="selection", direction=direction) for h in parsed.hints
        ]
        if not parsed.hints and (named_colours(intent.text or "") or direction):
            parsed.hints = [_edit_hint(intent.text or "")]
        return parsed
    if volume is None:
        return parsed
    exact: dict[str, tuple] = {}
    if not parsed.hints and intent.kind == "image" and intent.reference is not None:
        parsed, exact = _reference_hints(intent.reference)
    counts, _ = volume.histogram()
    if structures is None and any(
        h.role in ("part", "skin") or h.material == "bone" for h in parsed.hints
    ):
        structures = structure_map_of(volume)
    placed = place_hints(
        parsed, counts, tuple(volume.value_range), getattr(volume, "original_dtype", None),
        structures=structures,
    )  # fmt: skip
    if exact:  # a reference picture's own colours, not their nearest names
        placed.hints = [_with(h, rgb=exact.get(h.words, h.rgb)) for h in placed.hints]
    return placed


def _reference_hints(image) -> tuple[TextHints, dict[str, tuple]]:
    """A reference picture's layers as parsed words, and each layer's exact colour by words."""
    from intuitf.intent.reference import reference_layers, reference_words

    layers = reference_layers(image)
    if not layers:
        return parse_text(None), {}
    words = reference_words(layers)
    parsed = parse_text(words)
    parsed.notes.append("from the reference picture: " + words)
    exact = {f"{kind} part": rgb for kind, rgb, _ in layers}
    return parsed, exact


_MAPS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def structure_map_of(volume) -> StructureMap:
    """The structure map of ``volume`` (built once per volume object and kept with it).

    A map given to :func:`remember_structure_map` (one read from disk, or one a model named)
    is used instead of building one.
    """
    smap = _MAPS.get(volume)
    if smap is None:
        from intuitf.intent.structures import build_structure_map

        counts, _ = volume.histogram()
        smap = build_structure_map(volume.data, counts, tuple(volume.spacing))
        _MAPS[volume] = smap
    return smap


def known_structure_map(volume) -> StructureMap | None:
    """``volume``'s structure map if one was built or remembered already (None: not yet)."""
    return _MAPS.get(volume)


def remember_structure_map(volume, smap: StructureMap) -> None:
    """Use ``smap`` as ``volume``'s structure map from now on (a cached or named one)."""
    _MAPS[volume] = smap


def _edit_hint(text: str) -> MaterialHint:
    low = text.lower()
    names = named_colours(low)
    colour = names[0] if names else None
    rgb = tuple(float(c) / 255.0 for c in NAMED_COLOURS[colour]) if colour else None
    return MaterialHint(
        clause=low, material="selection", words="the selection", colour=colour,
        rgb=rgb, opacity=_look(low), placed_by="selection",  # type: ignore[arg-type]
        direction=edit_direction(low),
    )  # fmt: skip


@dataclass
class IntentReading:
    """What an intent says about single materials on a volume: its words' hints (``text``)
    and, for a sketch, one hint per stroke (:class:`intuitf.intent.strokes.StrokeHint`).
    Read once per run, it gives the Explorer its hints (:func:`explorer_hints`) and a person
    the lines of :func:`intuitf.intent.readback.read_back`."""

    text: TextHints
    strokes: list = field(default_factory=list)


def read_intent(
    intent: Intent, volume=None, structures: StructureMap | None = None, camera=None
) -> IntentReading:
    """The words' hints of ``intent`` on ``volume``, and a sketch's strokes where a ``camera``
    (its base picture's, a ``Camera`` or its dict) says how they lie on it."""
    th = intent_hints(intent, volume, structures)
    strokes = []
    if intent.kind == "sketch" and intent.sketch is not None and volume is not None and camera:
        strokes = _stroke_hints(intent, volume, camera)  # rays through every stroke
    return IntentReading(th, strokes)


def explorer_hints(
    intent: Intent,
    volume=None,
    structures: StructureMap | None = None,
    camera=None,
    reading: IntentReading | None = None,
) -> list[dict]:
    """The hints the Explorer takes for ``intent`` on ``volume`` (empty: none understood).

    Whatever the intent (text, picture, sketch, or none), the background's values get a
    hint of their own: hidden, unless the words name air. Nobody asks for the empty space
    around the object to be painted, and a faint Gaussian there is a veil over the whole
    volume box. Values under the background's mode (padding outside a scanner's field of
    view) get a hidden "padding" hint too. (An edit changes selected features only: it gets
    no background hint.)

    A sketch, with the ``camera`` its base picture was rendered from (a ``Camera`` or its
    dict), gives a hint per stroke: its colour on the values under it
    (:func:`intuitf.intent.strokes.stroke_hints`). ``reading``: the intent already read
    (:func:`read_intent`), so that nothing is read twice.
    """
    reading = reading or read_intent(intent, volume, structures, camera)
    th, strokes = reading.text, reading.strokes
    out = [h.to_explorer() for h in th.hints if h.center is not None or intent.kind == "edit"]
    placed = [h for h in th.hints if h.center is not None]
    out += [h.to_explorer() for h in strokes]
    placed = placed + [_with_place(h) for h in strokes]
    if intent.kind != "edit" and volume is not None and not any(h.role == "air" for h in placed):
        counts, _ = volume.histogram()
        layout = _Layout.of(np.asarray(counts, dtype=np.float64), _materials(counts))
        top = min([layout.cutoff] + [h.center - 2.5 * h.spread for h in placed])
        spread = 0.0
        if top > layout.background + 0.01:
            # Reaches (2.5 spreads) from the background's mode up to just below the cutoff.
            spread = (top - layout.background) / 2.5
            out.append(
                {"name": "background", "center": layout.background, "spread": spread,
                 "color": None, "height": None, "hidden": True}
            )  # fmt: skip
        below = layout.background - spread
        if below > 0.01 and not any(h.center - 2.5 * h.spread < below for h in placed):
            # Values under the background's mode (a scanner's padding outside its field of
            # view, an empty face of the box) are background too: lit, they paint a face of
            # the box. One spread below 0 to 2.5 above the gap's top covers them.
            s = below / 3.5
            out.append(
                {"name": "padding", "center": s, "spread": s, "color": None, "height": None,
                 "hidden": True}
            )  # fmt: skip
    return out


def _stroke_hints(intent: Intent, volume, camera) -> list:
    from intuitf.intent.strokes import stroke_hints

    cam, cut = stroke_rays(volume, camera)
    return stroke_hints(intent.sketch, volume.data, tuple(volume.spacing), cam, cut)


def stroke_rays(volume, camera):
    """What a stroke's rays need besides the volume's array: the ``Camera`` (from a
    ``Camera`` or its dict) and the background's upper value, where a ray enters the object."""
    from intuitf.render.camera import Camera
    from intuitf.tf.defaults import background_cutoff

    cam = camera if isinstance(camera, Camera) else Camera.from_dict(dict(camera))
    counts, _ = volume.histogram()
    return cam, background_cutoff(np.asarray(counts, dtype=np.float64))


def _with_place(h) -> MaterialHint:
    """A stroke hint seen as a placed material (for the background's reach)."""
    return MaterialHint(clause="", material="stroke", words="stroke", center=h.center,
                        spread=h.spread, placed_by="stroke")  # fmt: skip


def _materials(counts):
    from intuitf.tf.defaults import find_materials

    return find_materials(np.asarray(counts, dtype=np.float64).ravel(), max_materials=6)
