"""The structure map of a volume: its materials split into 3-D parts, each with descriptors.

Words name structures ("the pot", "the leaves", "the root", "the outer part"), not value ranges.
A structure here is one 3-D connected part of one material of the histogram; its descriptors are
what a word can be matched against:

- **values**: the material's value interval and the part's own 5-95 % value range;
- **size**: voxel count and share of the foreground;
- **position**: centroid along each data axis (0 = low end, 1 = high end), "bottom"/"top"/
  "centre" along the volume's up axis, and whether the part is *outer* (touches the air around
  the object) or *inner* (enclosed by other parts), and which part encloses it;
- **shape**: from the principal extents (PCA of the voxel positions, in physical units) and the
  thickness (twice the mean distance to the part's surface): *thin* (thickness small against the
  length), *elongated* (one extent dominates), *plate* (two dominate the third), *blob*
  (compact, solid), *shell* (hollow: filling its holes adds much volume), *branching* (thin and
  split into many pieces, or its skeleton has many ends), *scattered* (many small pieces);
- **background**: the lowest material's part that touches the volume's border (air, the
  embedding, noise); a material made of specks only is noise.

One material's connected piece can be two things a word names: the soil an open container
holds and the trunk rising out of it are split in two (:func:`held_by`).

Everything is computed on a copy of the volume reduced to at most ``max_dim`` voxels per axis
(the map is about parts a word can name, not about voxels), except the upper end of each part's
value range, read from the volume's own voxels (block averages pull a thin part's values toward
the air around it). The map is pure data: building and caching are separate
(:func:`build_structure_map` computes; the session caches the JSON form beside the volume's
other caches, see :meth:`StructureMap.to_dict`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import ndimage

from intuitf.tf.defaults import background_cutoff, find_materials

#: The version of the decomposition: a cached map of another version is built again.
STRUCTURE_MAP_VERSION = 3
#: Parts smaller than this share of the foreground are specks (merged into the material's rest).
MIN_PART_SHARE = 0.004
#: At most this many parts per material are kept as structures (the largest).
MAX_PARTS = 6
#: A material whose largest part holds less than this share of it is scattered (leaves, noise).
SCATTERED = 0.35
#: A part that an open container of another material holds this share of, at least, is two
#: parts when enough of it rises out of the container: what the container holds and what
#: rises out (the soil in the bonsai's pot and its trunk, one connected piece of one material).
HELD = 0.2


@dataclass(frozen=True)
class Structure:
    """One part of one material, with what a word can be matched against (module docstring)."""

    id: int
    material: int  # index into StructureMap.materials (0: background)
    value_range: tuple[float, float]  # normalised 5-95 % of the part's voxel values
    material_range: tuple[float, float]  # the material's whole value interval
    voxels: int
    share: float  # of the foreground's voxels
    centroid: tuple[float, float, float]  # (x, y, z), 0..1 along each axis of the box
    height: float  # 0 bottom .. 1 top along the map's up axis
    position: str  # "bottom", "centre", "top"
    outer: bool  # touches the air around the object
    enclosed_by: int | None  # the structure that surrounds it, if any
    extents: tuple[float, float, float]  # principal extents, largest first (physical units)
    thickness: float  # twice the mean inner distance (physical units)
    pieces: int  # connected pieces (a scattered part: many)
    shape: str  # "thin", "elongated", "branching", "plate", "blob", "shell", "scattered"
    background: bool = False
    name: str | None = None  # given by a model or a label atlas
    #: (x0, y0, z0, x1, y1, z1), 0..1 along each axis of the box
    bbox: tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.0, 1.0, 1.0, 1.0)

    @property
    def center(self) -> float:
        """The middle of the part's value range (normalised)."""
        return 0.5 * (self.value_range[0] + self.value_range[1])

    def describe(self) -> str:
        """One line a person (or a model) can read: 'S3: blob, bottom, outer, 31 % ...'."""
        where = "outer" if self.outer else "inner"
        bits = [
            f"S{self.id}",
            "background" if self.background else self.shape,
            self.position,
            where,
            f"{100 * self.share:.1f} % of the object",
            f"values {self.value_range[0]:.2f}-{self.value_range[1]:.2f}",
        ]
        if self.enclosed_by is not None:
            bits.append(f"inside S{self.enclosed_by}")
        if self.name:
            bits.append(f'named "{self.name}"')
        return ", ".join(bits)


@dataclass
class StructureMap:
    """All structures of a volume, the materials they come from, and the up axis used."""

    materials: list[tuple[float, float]]  # value intervals, lowest first (0: background)
    structures: list[Structure] = field(default_factory=list)
    up_axis: int = 2  # 0 x, 1 y, 2 z
    up_sign: int = 1
    shape: tuple[int, int, int] = (0, 0, 0)  # of the reduced grid (z, y, x)
    #: Structure id + 1 per voxel of the reduced grid (0: none), with the reduced grid's voxel
    #: size (z, y, x); kept in memory only (not in :meth:`to_dict`).
    labels: np.ndarray | None = field(default=None, repr=False, compare=False)
    voxel_size: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def foreground(self) -> list[Structure]:
        return [s for s in self.structures if not s.background]

    def background(self) -> list[Structure]:
        return [s for s in self.structures if s.background]

    def by_id(self, sid: int) -> Structure:
        for s in self.structures:
            if s.id == sid:
                return s
        raise KeyError(f"No structure S{sid}.")

    def named(self, names: dict[int, str]) -> StructureMap:
        """A copy with the given names (structure id -> name)."""
        from dataclasses import replace

        out = [replace(s, name=names.get(s.id, s.name)) for s in self.structures]
        return StructureMap(list(self.materials), out, self.up_axis, self.up_sign, self.shape,
                            self.labels, self.voxel_size)  # fmt: skip

    def to_dict(self) -> dict:
        return {
            "materials": [list(m) for m in self.materials],
            "up_axis": self.up_axis,
            "up_sign": self.up_sign,
            "shape": list(self.shape),
            "structures": [asdict(s) for s in self.structures],
        }

    @classmethod
    def from_dict(cls, d: dict) -> StructureMap:
        ss = []
        for s in d.get("structures", []):
            s = dict(s)
            for k in ("value_range", "material_range", "centroid", "extents", "bbox"):
                if k not in s:
                    continue
                s[k] = tuple(s[k])
            ss.append(Structure(**s))
        return cls(
            [tuple(m) for m in d["materials"]],  # type: ignore[misc]
            ss,
            int(d.get("up_axis", 2)),
            int(d.get("up_sign", 1)),
            tuple(d.get("shape", (0, 0, 0))),  # type: ignore[arg-type]
        )

    def summary(self) -> str:
        return "\n".join(s.describe() for s in self.structures)


# -- building ----------------------------------------------------------------------------------


def reduce(data: np.ndarray, max_dim: int) -> tuple[np.ndarray, int]:
    """``data`` block-averaged so that no axis exceeds ``max_dim`` (and the factor used)."""
    f = max(1, int(np.ceil(max(data.shape) / float(max_dim))))
    if f == 1:
        return np.asarray(data, dtype=np.float32), 1
    z, y, x = (s // f * f for s in data.shape)
    d = np.asarray(data[:z, :y, :x], dtype=np.float32)
    return d.reshape(z // f, f, y // f, f, x // f, f).mean(axis=(1, 3, 5)), f


def material_intervals(counts: np.ndarray) -> list[tuple[float, float]]:
    """The histogram's materials as value intervals: background first, then each material.

    The background is everything below :func:`~intuitf.tf.defaults.background_cutoff`; the
    materials above it are split at the lowest point of the histogram between two peaks.
    """
    c = np.asarray(counts, dtype=np.float64).ravel()
    n = c.size
    cut = background_cutoff(c)
    mats = [m for m in find_materials(c, max_materials=6) if m.center > cut + 1.0 / n]
    centres = sorted({round(m.center, 4) for m in mats})
    smooth = ndimage.gaussian_filter1d(np.log1p(c), 1.5)
    edges = [cut]
    for a, b in zip(centres, centres[1:], strict=False):
        ia, ib = int(a * n), max(int(a * n) + 1, int(b * n))
        edges.append((ia + int(np.argmin(smooth[ia:ib]))) / n)
    edges.append(1.0 + 1e-6)
    out = [(0.0, cut)]
    for a, b in zip(edges, edges[1:], strict=False):
        if b - a > 1.0 / n:
            out.append((float(a), float(min(b, 1.0))))
    return out


def up_axis_of(fg: np.ndarray) -> tuple[int, int]:
    """The data axis (0 x, 1 y, 2 z) and direction the object stands along.

    Scanners store most objects with z along their long axis (patients, teeth, engines), so z
    is up unless another axis is clearly the object's base: the axis along which the lower
    end's slab holds most of the foreground and the upper end's little (a pot under a tree).
    """
    best, best_score = (2, 1), 0.0
    zyx = fg.astype(np.float32)
    for ax_data, ax_arr in ((0, 2), (1, 1), (2, 0)):
        prof = zyx.sum(axis=tuple(a for a in range(3) if a != ax_arr))
        if prof.sum() <= 0:
            continue
        prof = prof / prof.sum()
        k = max(1, len(prof) // 4)
        low, high = float(prof[:k].sum()), float(prof[-k:].sum())
        for sign, base, top in ((1, low, high), (-1, high, low)):
            score = base - 2.0 * top
            if score > best_score:
                best, best_score = (ax_data, sign), score
    if best[0] == 2 or best_score < 0.3:
        # The scanner's convention (a tooth's crown is wider than its root, so "the wide end
        # is the base" does not hold along z), except for a head scanned from the top down.
        return 2, _z_sign(zyx)
    return best


#: A z end whose slabs (1/16 of the slices) hold at most this share of the largest cross
#: section is closed (a dome: the top of a skull); at least ``CUT_END`` is cut by the box.
CLOSED_END, CUT_END = 0.12, 0.3


def _z_sign(fg: np.ndarray) -> int:
    """+1, unless the object is closed like a dome at the low z end and cut by the box at the
    high end: then it is a head (or body part) stored from its top down, and -z is up.

    A CT of a head starts at the top of the skull or at the neck. The skull's top is a closed
    dome; the neck is cut by the scan's end. So the closed end is the top. Objects closed at
    both ends (a tooth) or cut at the low end (a foot on its sole, a chest) keep +z.
    """
    prof = fg.sum(axis=(1, 2)).astype(np.float64)  # cross-section per z slice
    if prof.max() <= 0:
        return 1
    prof /= prof.max()
    k = max(1, len(prof) // 16)
    low, high = float(prof[:k].mean()), float(prof[-k:].mean())
    return -1 if low <= CLOSED_END and high >= CUT_END else 1


def build_structure_map(
    data: np.ndarray,
    counts: np.ndarray | None = None,
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0),
    max_dim: int = 64,
) -> StructureMap:
    """Decompose a normalised volume (``data[z, y, x]`` in [0, 1]) into structures.

    ``counts`` is the histogram over [0, 1] (256 bins from ``data`` when not given); ``spacing``
    the voxel size along (x, y, z). See the module docstring for the descriptors.
    """
    if counts is None:
        counts, _ = np.histogram(np.asarray(data).ravel(), bins=256, range=(0.0, 1.0))
    small, f = reduce(np.asarray(data), max_dim)
    sp = np.asarray(spacing, dtype=np.float64)[::-1] * f  # (z, y, x) physical voxel size
    mats = material_intervals(np.asarray(counts))
    cls = np.zeros(small.shape, np.int16)
    for k, (a, b) in enumerate(mats):
        cls[(small >= a) & (small < b)] = k
    cls[small >= mats[-1][1]] = len(mats) - 1
    fg = cls > 0
    # The object's outside: background connected to the volume's border.
    bg_parts, _ = ndimage.label(~fg)
    border_ids = np.unique(
        np.concatenate(
            [bg_parts[0].ravel(), bg_parts[-1].ravel(), bg_parts[:, 0].ravel(),
             bg_parts[:, -1].ravel(), bg_parts[:, :, 0].ravel(), bg_parts[:, :, -1].ravel()]
        )
    )  # fmt: skip
    outside = np.isin(bg_parts, border_ids[border_ids > 0])
    near_outside = ndimage.binary_dilation(outside, iterations=1)
    up_ax, up_sign = up_axis_of(fg)
    # Heights are measured within the object's own extent along the up axis, not the box's.
    arr_ax = 2 - up_ax
    occupied = np.flatnonzero(fg.any(axis=tuple(a for a in range(3) if a != arr_ax)))
    span = (int(occupied[0]), int(occupied[-1])) if occupied.size else (0, shape_of(fg, arr_ax))
    n_fg = max(1, int(fg.sum()))
    structures: list[Structure] = []
    masks: list[np.ndarray] = []
    shape = small.shape
    struct26 = np.ones((3, 3, 3), bool)
    # Background: the outside itself (air, embedding, noise touching the border).
    if outside.any():
        structures.append(
            _describe(0, 0, outside, small, mats[0], shape, sp, up_ax, up_sign, n_fg,
                      near_outside, pieces=1, background=True, span=span)
        )  # fmt: skip
        masks.append(outside)
    for k in range(1, len(mats)):
        mk = cls == k
        total = int(mk.sum())
        if total == 0:
            continue
        lab, n = ndimage.label(mk, structure=struct26)
        sizes = np.bincount(lab.ravel(), minlength=n + 1)[1:]
        order = np.argsort(sizes)[::-1]
        largest_share = float(sizes[order[0]] / total) if n else 0.0
        if largest_share < SCATTERED:
            # Many pieces of one material (leaves, noise): one scattered structure.
            structures.append(
                _describe(len(structures), k, mk, small, mats[k], shape, sp, up_ax, up_sign,
                          n_fg, near_outside, pieces=int(n), scattered=True, span=span)
            )  # fmt: skip
            masks.append(mk)
            continue
        rest = np.zeros_like(mk)
        for j in order[:MAX_PARTS]:
            if sizes[j] < MIN_PART_SHARE * n_fg:
                break
            part = lab == (j + 1)
            structures.append(
                _describe(len(structures), k, part, small, mats[k], shape, sp, up_ax, up_sign,
                          n_fg, near_outside, pieces=1, span=span)
            )  # fmt: skip
            masks.append(part)
        del rest
    structures, masks = _split_held(
        structures, masks,
        lambda sid, k, m: _describe(sid, k, m, small, mats[k], shape, sp, up_ax, up_sign, n_fg,
                                    near_outside, pieces=1, span=span),
        arr_ax, up_sign, float(sp[arr_ax]), n_fg,
    )  # fmt: skip
    structures = _enclosure(structures, masks)
    labels = np.zeros(shape, np.int16)
    for st, m in zip(structures, masks, strict=True):
        labels[m & (labels == 0)] = st.id + 1
    if f > 1:
        structures = _full_value_ranges(structures, labels, np.asarray(data), f, mats)
    return StructureMap(
        mats, structures, up_ax, up_sign, tuple(int(s) for s in shape),  # type: ignore[arg-type]
        labels, tuple(float(v) for v in sp),  # type: ignore[arg-type]
    )  # fmt: skip


def _full_value_ranges(
    structures: list[Structure], labels: np.ndarray, data: np.ndarray, f: int,
    mats: list[tuple[float, float]],
) -> list[Structure]:  # fmt: skip
    """Each part's value range widened to its own voxels' 5-95 % range.

    Block averages pull a thin part's values toward the air around it (a rod three voxels
    across, in cells of four, averages to under 60 % of its value): the bonsai's trunk read
    0.29-0.54 at 64³, and its colour, placed on those values, fell on the rims of everything
    denser (the pot's outer surface passes through them) more than on the trunk. The upper
    end is read from the part's own voxels (those of its cells within its material's
    interval, every second one along each axis); the lower end stays the lower of the two,
    as for a thick part the grid's averages there are its surface, which is what shows it
    (placed on the voxels' range alone, the engine's casing colour moved off its surface and
    the first generation's casing went from ΔE 7 to 20).
    """
    from dataclasses import replace

    step = 2
    idx = [np.minimum(np.arange(0, n, step) // f, m - 1) for n, m in zip(data.shape, labels.shape,
                                                                       strict=True)]  # fmt: skip
    lab = labels[np.ix_(*idx)]
    vals = np.asarray(data[::step, ::step, ::step], dtype=np.float32)
    out = []
    for st in structures:
        if st.background:
            out.append(st)
            continue
        a, b = mats[st.material]
        own = vals[(lab == st.id + 1) & (vals >= a) & (vals < max(b, a + 1e-6))]
        if own.size < 20:
            out.append(st)
            continue
        lo, hi = (float(v) for v in np.percentile(own, [5, 95]))
        out.append(replace(st, value_range=(min(lo, st.value_range[0]),
                                            max(hi, st.value_range[1]))))  # fmt: skip
    return out


def shape_of(a: np.ndarray, axis: int) -> int:
    return int(a.shape[axis]) - 1


def _describe(
    sid, k, mask, small, mat, shape, sp, up_ax, up_sign, n_fg, near_outside, *, pieces,
    background=False, scattered=False, span=None,
) -> Structure:  # fmt: skip
    idx = np.argwhere(mask)  # (z, y, x)
    vals = small[mask]
    lo, hi = (float(v) for v in np.percentile(vals, [5, 95]))
    norm = np.maximum(np.asarray(shape) - 1, 1)
    cen = idx.mean(axis=0) / norm
    lo_c, hi_c = idx.min(axis=0) / norm, idx.max(axis=0) / norm
    bbox = (float(lo_c[2]), float(lo_c[1]), float(lo_c[0]),
            float(hi_c[2]), float(hi_c[1]), float(hi_c[0]))  # fmt: skip
    centroid = (float(cen[2]), float(cen[1]), float(cen[0]))
    arr_ax = 2 - up_ax
    lo_i, hi_i = span if span is not None else (0, shape[arr_ax] - 1)
    h = (float(idx[:, arr_ax].mean()) - lo_i) / max(1.0, float(hi_i - lo_i))
    h = float(np.clip(h if up_sign > 0 else 1.0 - h, 0.0, 1.0))
    position = "bottom" if h < 0.38 else ("top" if h > 0.62 else "centre")
    pts = idx * sp
    if len(pts) > 20000:
        pts = pts[:: len(pts) // 20000 + 1]
    cov = np.cov((pts - pts.mean(axis=0)).T) if len(pts) > 3 else np.zeros((3, 3))
    ev = np.sort(np.clip(np.linalg.eigvalsh(cov), 0, None))[::-1]
    extents = tuple(float(4.0 * np.sqrt(e)) for e in ev)  # ~ full length of a uniform bar
    edt = ndimage.distance_transform_edt(mask, sampling=sp)
    thickness = float(2.0 * edt[mask].mean()) if mask.any() else 0.0
    # Outer: a fair share of the part's own surface faces the air around the object.
    surface = mask & ~ndimage.binary_erosion(mask)
    exposed = float((surface & near_outside).sum()) / max(1.0, float(surface.sum()))
    outer = exposed > 0.25
    if background:
        shape_word = "background"
    elif scattered:
        shape_word = "scattered"
    else:
        shape_word = _shape_word(mask, extents, thickness)  # type: ignore[arg-type]
    return Structure(
        id=int(sid), material=int(k), value_range=(lo, hi),
        material_range=(float(mat[0]), float(mat[1])), voxels=int(mask.sum()),
        share=float(mask.sum() / n_fg) if not background else 0.0, centroid=centroid,
        height=float(h), position=position, outer=outer, enclosed_by=None,
        extents=extents, thickness=thickness, pieces=int(pieces), shape=shape_word,  # type: ignore[arg-type]
        background=background, bbox=bbox,
    )  # fmt: skip


def _shape_word(mask: np.ndarray, extents: tuple[float, float, float], thickness: float) -> str:
    """thin / elongated / branching / plate / blob / shell (see the module docstring)."""
    l1, l2, l3 = (max(e, 1e-6) for e in extents)
    filled = ndimage.binary_fill_holes(mask)
    hollow = float(filled.sum()) / max(1.0, float(mask.sum()))
    if hollow > 1.6:
        return "shell"
    thin = thickness < 0.12 * l1
    if thin and l2 / l1 > 0.45:
        # Thin everywhere yet spread in two or three directions: a plate (or a bowl) when its
        # third extent is small against its second, else branches (a tree's crown of boughs
        # spreads as far in depth as in width).
        return "branching" if l3 / l2 > 0.5 else "plate"
    if l1 / l2 > 2.2:
        return "thin" if thin else "elongated"
    if l2 / max(l3, 1e-6) > 2.5 and thickness < 0.2 * l2:
        return "plate"
    return "blob"


def slice_hulls(mask: np.ndarray, axis: int) -> np.ndarray:
    """Each slice across the up axis (array ``axis``) filled to the convex hull of ``mask``'s
    cross-section there: what a container's walls surround (a pot's ring becomes a disc)."""
    from skimage.morphology import convex_hull_image

    out = np.zeros_like(mask)
    for i in range(mask.shape[axis]):
        sl = [slice(None)] * 3
        sl[axis] = i
        cut = mask[tuple(sl)]
        if cut.sum() >= 3:
            out[tuple(sl)] = convex_hull_image(cut)
    return out


def held_by(
    part: np.ndarray,
    container: np.ndarray,
    container_thickness: float,
    axis: int,
    sign: int,
    voxel: float,
    hulls: np.ndarray | None = None,
) -> np.ndarray | None:
    """The voxels of ``part`` that the open ``container`` holds, or None when it holds too
    little of it (:data:`HELD`) or is closed at the top.

    A container holds what lies over its footprint (the hull of its outline seen along the up
    axis) from its bottom up to one wall's thickness above its rim, the soil heaped in a pot
    included. It holds it when its walls surround most of that: per slice across the up axis,
    the hull of the container's cross-section (:func:`slice_hulls`) holds at least 60 % of it
    (the bone of a foot lies over the footprint of its skin, but the skin is outside the
    bone's walls). ``hulls``: the container's :func:`slice_hulls`, when already at hand.
    """
    from skimage.morphology import convex_hull_image

    ax_other = tuple(a for a in range(3) if a != axis)
    levels = np.flatnonzero(container.any(axis=ax_other))
    if levels.size == 0:
        return None
    margin = int(np.ceil(container_thickness / max(voxel, 1e-9)))
    idx = np.arange(container.shape[axis]).reshape([-1 if a == axis else 1 for a in range(3)])
    below = idx <= levels[-1] + margin if sign > 0 else idx >= levels[0] - margin
    footprint = np.expand_dims(convex_hull_image(container.any(axis=axis)), axis)
    held = part & footprint & below & ~container
    hulls = slice_hulls(container, axis) if hulls is None else hulls
    walled = int((held & hulls).sum())
    if walled < max(HELD * part.sum(), 0.6 * held.sum()):
        return None
    # Open at the top, and the part passes through the opening: at the container's top (its
    # highest slice of a fair cross-section, not a stray voxel) its walls are a ring, not a
    # cap, and the part lies inside the ring. A skull's top is a closed cap: the brain it
    # holds does not reach through it to the scalp above.
    area = container.sum(axis=ax_other)[levels]
    fair = levels[area >= 0.2 * np.median(area)]
    top = int(fair[-1] if sign > 0 else fair[0])
    cut = [slice(None)] * 3
    cut[axis] = slice(top, top + 1)
    inside = (hulls & ~container)[tuple(cut)]
    if inside.sum() < 0.25 * hulls[tuple(cut)].sum() or not (part[tuple(cut)] & inside).any():
        return None
    return held


def _rises(piece: np.ndarray, container: np.ndarray, axis: int, sign: int) -> bool:
    """Whether ``piece`` rises above ``container``'s rim by at least half the container's
    own height (a trunk out of its pot, not a rim of soil heaped over it)."""
    other = tuple(a for a in range(3) if a != axis)
    c, p = np.flatnonzero(container.any(axis=other)), np.flatnonzero(piece.any(axis=other))
    if c.size == 0 or p.size == 0:
        return False
    above = (p[-1] - c[-1]) if sign > 0 else (c[0] - p[0])
    return bool(above >= 0.5 * (c[-1] - c[0] + 1))


def _split_held(
    structures: list[Structure], masks: list[np.ndarray], describe, axis: int, sign: int,
    voxel: float, n_fg: int,
) -> tuple[list[Structure], list[np.ndarray]]:  # fmt: skip
    """Parts that a container of another material holds in part are split in two.

    One material, one connected piece, two things a word names: the bonsai's soil fills its pot
    and its trunk rises out of it, and at the map's resolution they touch. The piece the
    container holds (:func:`held_by`) and the largest connected piece rising out of it (at
    least :data:`MIN_PART_SHARE` of the object; smaller bits stay with the held piece) become
    two structures, the one rising out first. Background, scattered parts and shells (they hold,
    they are not held) are never split.
    """
    from dataclasses import replace

    solid = [i for i, s in enumerate(structures)
             if not s.background and s.shape not in ("scattered", "shell")]  # fmt: skip
    hulls: dict[int, np.ndarray] = {}
    out_s: list[Structure] = []
    out_m: list[np.ndarray] = []
    for i, s in enumerate(structures):
        pieces = [masks[i]]
        for j in solid if i in solid else []:
            if j == i or structures[j].material == s.material:
                continue
            if j not in hulls:
                hulls[j] = slice_hulls(masks[j], axis)
            held = held_by(masks[i], masks[j], structures[j].thickness, axis, sign, voxel,
                           hulls[j])  # fmt: skip
            if held is None:
                continue
            lab, n = ndimage.label(masks[i] & ~held, structure=np.ones((3, 3, 3), bool))
            if n == 0:
                continue
            sizes = np.bincount(lab.ravel())[1:]
            risen = lab == int(np.argmax(sizes)) + 1
            if sizes.max() >= MIN_PART_SHARE * n_fg and _rises(risen, masks[j], axis, sign):
                pieces = [risen, masks[i] & ~risen]
                break
        for m in pieces:
            sid = len(out_s)
            out_s.append(replace(s, id=sid) if len(pieces) == 1 else describe(sid, s.material, m))
            out_m.append(m)
    return out_s, out_m


def _enclosure(structures: list[Structure], masks: list[np.ndarray]) -> list[Structure]:
    """Each inner structure's enclosing one: the smallest structure whose filled form holds
    most of it."""
    from dataclasses import replace

    filled = [ndimage.binary_fill_holes(m) if not s.background else None
              for s, m in zip(structures, masks, strict=True)]  # fmt: skip
    out = []
    for i, s in enumerate(structures):
        best, best_size = None, None
        if not s.background:
            for j, t in enumerate(structures):
                if j == i or t.background or filled[j] is None:
                    continue
                inside = float((masks[i] & filled[j]).sum()) / max(1, s.voxels)
                if inside > 0.8 and t.voxels > 0 and (best_size is None or t.voxels < best_size):
                    best, best_size = t.id, t.voxels
        out.append(replace(s, enclosed_by=best))
    return out
