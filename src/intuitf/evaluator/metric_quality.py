"""What the offline judge measures for quality: clear structure, not haze, speckle or one shell.

The paper's information-entropy baseline rewards noise: a faint Gaussian over the background's
noisy values paints a grey veil over the whole volume box, and the veil adds colours, so
entropy goes up. People reject such a picture at once. These measures keep the entropy of
what is clearly shown, and scale it by what people look for (all on a 128 x 128 copy of the
image, so that renderings of any size compare alike):

- **veil** (haze): share of the foreground that is dim (within ΔE 40 of the background) and
  nearly colourless (CIELAB saturation C*/sqrt(C*² + L*²) below 0.25), and an area rather
  than a line (what survives a 3 x 3 opening): a grey fog over empty space. Faint context
  that carries a colour (a translucent red skin) is not veil, unless it is barely seen
  (within ΔE 8 of the background: a tinted murk over the box). Up to a tenth of the
  foreground is tolerated; beyond that the clarity falls with the square of the excess.
- **box**: when the silhouette is the volume's box (a convex polygon of a few straight
  sides, or a hexagon at most that fits it closely when parts of the object stick out of it:
  :func:`box_silhouette`), the background's own values are painted: every nearly
  colourless foreground pixel counts as veil however bright, and so does every faint one
  (within ΔE 40 of the background) whatever its colour, and the clarity is halved.
- **grain** (noise): the ratio of speckle's fine-scale lightness energy to the medium-scale
  energy (σ = 0.8 minus σ = 2.5 px blur). Fine energy is the image minus its σ = 0.8 px blur;
  speckle is the part of it in specks: connected runs of at most 4 pixels that stand out of
  that blur (by more than the fine energy's standard deviation, brighter or darker). Edges of
  real structures carry energy at both scales, speckle only at the fine one; and thin
  structures (ribs, vessels, branches at 128 px) carry fine energy too, but in lines, not
  specks: counted whole, a rib cage read as noisier than the speckle of a noise Gaussian
  (grain 1.32 against 1.07-1.78), and no search showed ribs crisply. Grain above 0.5 lowers
  the clarity exponentially.
- **separation**: spread of the clearly shown pixels in the CIELAB a*b* plane (the standard
  deviation of their chroma coordinates): materials told apart by colour. A single opaque
  shell, one colour with shading, has little; washed-out colours have none.
- **crispness**: the 90th percentile of the lightness gradient (σ = 1 px) in the clearly
  shown pixels, /10: boundaries that are sharp rather than smeared.

``clarity = (1 - max(0, veil - 0.1) / 0.9)² · exp(-3 · max(0, grain - 0.5)) · (0.5 if box)``,
in [0, 1].
Information richness is ``entropy of the clear pixels' colours · sqrt(their coverage) ·
min(1, coverage / 0.02) · clarity · (0.4 + 0.6 · min(1, separation / 25))`` (a speck under
2 % of the picture, however colourful, is not an informative rendering; the grain kept such
specks down once, when it counted all fine energy); feature discrimination is
``(min(1.5, separation / 20) + 0.3 · min(1, crispness)) · clarity``. A blank picture scores 0
on both. The constants were set on the labelled pairs in ``tests/data/judge_pairs`` (built by
``benchmarks/judge_pairs.py``) and checked on pairs of six volumes that set does not hold
(``judge_pairs.py build --holdout``).

What it cannot see: whether a structure that is shown is the one that matters (an opaque skin
and an opaque skull both look clear), whether something is hidden behind an opaque surface
that shows structure itself, and taste. A shell is caught only by its lack of colour
separation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.color import rgb2lab
from skimage.measure import approximate_polygon, find_contours
from skimage.morphology import convex_hull_image
from skimage.transform import resize

#: Side of the square copy the quality measures are taken on.
SIDE = 128
#: Foreground pixels within this ΔE of the background and below this saturation are veil.
VEIL_DELTA_E = 40.0
VEIL_SATURATION = 0.25
#: Foreground pixels this close to the background are veil whatever their colour (barely seen).
VEIL_DIM = 8.0
#: A silhouette that fills this much of its convex hull, with an outline of at most this many
#: straight sides (2 px tolerance) and at least this share of the picture, is the volume's box.
BOX_SOLIDITY = 0.95
BOX_SIDES = 9
BOX_AREA = 0.1
#: ... or, when bits stick out of it, a hexagon at most fits it this well (IoU).
BOX_FIT = 0.93
#: Clarity kept when the box shows (the background itself is painted).
BOX_PENALTY = 0.5
#: Share of the foreground that may be veil before the clarity falls.
VEIL_TOLERATED = 0.1
#: Grain (speckle's fine over medium energy) above which the clarity falls, and how fast.
GRAIN_FREE = 0.5
GRAIN_RATE = 3.0
#: Largest run of pixels (4-connected) that counts as a speck, not a line, in the grain.
SPECK_PIXELS = 4
#: a*b* spread at which colour separation counts fully (richness) / per unit (discrimination).
SEPARATION_FULL = 25.0
SEPARATION_UNIT = 20.0
#: Clear coverage below which the richness falls in proportion (a speck, not a rendering).
SMALL_COVERAGE = 0.02


@dataclass(frozen=True)
class Quality:
    """The quality measures of one picture (see the module docstring)."""

    coverage: float  # share of the picture that is clearly shown (foreground minus veil)
    box: bool  # the silhouette is the volume's box: its empty space is painted
    veil: float  # share of the foreground that is veil
    grain: float  # fine/medium energy ratio of the foreground's lightness
    separation: float  # a*b* spread of the clearly shown pixels
    crispness: float  # 90th percentile lightness gradient /10 there
    entropy: float  # bits of the clearly shown pixels' colour histogram
    clarity: float  # [0, 1]: 1 is free of veil and grain
    richness: float  # information richness
    discrimination: float  # feature discrimination

    def to_dict(self) -> dict:
        return dict(self.__dict__)


BLANK = Quality(0.0, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def box_silhouette(fg: np.ndarray) -> bool:
    """Whether the foreground's outline is the volume's box seen in perspective.

    Painting the background's values fills the whole box, and its silhouette becomes a
    convex polygon of four to six straight sides; the outline of an object is curved. The
    largest blob (holes filled) must fill its convex hull (:data:`BOX_SOLIDITY`), take
    :data:`BOX_AREA` of the picture, and follow a polygon of at most :data:`BOX_SIDES` sides.
    """
    filled = ndimage.binary_fill_holes(ndimage.binary_closing(fg, iterations=2))
    labels, n = ndimage.label(filled)
    if n == 0:
        return False
    sizes = ndimage.sum(filled, labels, range(1, n + 1))
    blob = labels == 1 + int(np.argmax(sizes))
    area = int(blob.sum())
    if area < BOX_AREA * blob.size:
        return False
    if area < BOX_SOLIDITY * int(convex_hull_image(blob).sum()):
        return False
    contour = max(find_contours(np.pad(blob, 1).astype(np.float32), 0.5), key=len)
    if len(approximate_polygon(contour, tolerance=2.0)) - 1 <= BOX_SIDES:
        return True
    # Something inside the box may stick out of its outline here and there (a pot at the
    # bottom of a bonsai's fog): the box is then still a hexagon at most that covers the blob.
    return _hexagon_fit(blob) >= BOX_FIT


def _hexagon_fit(blob: np.ndarray) -> float:
    """Intersection over union of ``blob`` and the polygon of at most six sides that
    approximates its convex hull (1 for a box seen in perspective; about 0.83 for a disc)."""
    from skimage.draw import polygon as fill_polygon

    hull = convex_hull_image(blob)
    contour = max(find_contours(np.pad(hull, 1).astype(np.float32), 0.5), key=len)
    for tol in (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0):
        poly = approximate_polygon(contour, tolerance=tol)
        if len(poly) - 1 <= 6:
            break
    else:
        return 0.0
    shape = (blob.shape[0] + 2, blob.shape[1] + 2)
    rr, cc = fill_polygon(poly[:, 0], poly[:, 1], shape)
    area = np.zeros(shape, bool)
    area[rr, cc] = True
    area = area[1:-1, 1:-1]
    union = float((area | blob).sum())
    return float((area & blob).sum()) / union if union else 0.0


def _entropy(counts: np.ndarray) -> float:
    total = counts.sum()
    if total <= 0:
        return 0.0
    p = counts[counts > 0] / total
    return float(-(p * np.log2(p)).sum())


def _grain(light: np.ndarray, fg: np.ndarray) -> float:
    """Speckle's fine-scale energy over the medium-scale energy of the foreground (the
    module docstring's **grain**)."""
    fine_blur = ndimage.gaussian_filter(light, 0.8)
    medium_blur = ndimage.gaussian_filter(light, 2.5)
    fine = light - fine_blur
    medium = float(np.abs(fine_blur - medium_blur)[fg].mean())
    step = float(np.abs(fine)[fg].std())
    specks = np.zeros(fg.shape, bool)
    for stands_out in (fine > step, fine < -step):
        runs, n = ndimage.label(stands_out & fg)
        if n:
            small = np.bincount(runs.ravel()) <= SPECK_PIXELS
            small[0] = False
            specks |= small[runs]
    return float(np.abs(fine)[specks].sum() / fg.sum()) / max(medium, 1e-6)


def quality(rgb: np.ndarray) -> Quality:
    """The quality measures of a uint8 RGB picture (H, W, 3)."""
    img = np.asarray(rgb, dtype=np.float32) / 255.0
    if img.shape[:2] != (SIDE, SIDE):
        img = resize(img, (SIDE, SIDE), anti_aliasing=True).astype(np.float32)
    img = np.clip(img, 0.0, 1.0)
    lab = rgb2lab(img).astype(np.float32)
    light = lab[..., 0]
    border = np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]])
    bg = np.median(border, axis=0)
    dist = np.linalg.norm(lab - bg, axis=2)
    fg = dist > 3.0
    n = int(fg.sum())
    if n < max(16, int(0.005 * fg.size)):
        return BLANK
    chroma = np.hypot(lab[..., 1], lab[..., 2])
    saturation = chroma / np.sqrt(chroma**2 + light**2 + 1e-6)
    box = box_silhouette(fg)
    dim = dist < (np.inf if box else VEIL_DELTA_E)  # in a painted box, bright fog too
    veil_px = fg & ((dim & (saturation < VEIL_SATURATION)) | (dist < VEIL_DIM))
    if box:
        # A painted box is fog in whatever colour: its faint pixels show no structure.
        veil_px |= fg & (dist < VEIL_DELTA_E)
    # A veil is an area: thin grey lines (fine vessels, edges seen at 128 px) are structure.
    veil_px = ndimage.binary_opening(veil_px, structure=np.ones((3, 3), bool))
    veil = float(veil_px.sum()) / n
    grain = _grain(light, fg)
    clear = fg & ~veil_px
    clarity = (1.0 - max(0.0, veil - VEIL_TOLERATED) / (1.0 - VEIL_TOLERATED)) ** 2
    clarity *= float(np.exp(-GRAIN_RATE * max(0.0, grain - GRAIN_FREE)))
    if box:
        clarity *= BOX_PENALTY
    if not clear.any():
        return Quality(0.0, box, veil, grain, 0.0, 0.0, 0.0, clarity, 0.0, 0.0)
    q = ((img[clear] * 255.0).astype(np.int32) // 32).clip(0, 7)
    entropy = _entropy(np.bincount(q[:, 0] * 64 + q[:, 1] * 8 + q[:, 2], minlength=512))
    ab = lab[clear][:, 1:].astype(np.float64)
    separation = float(np.sqrt(ab.var(axis=0).sum()))
    smooth = ndimage.gaussian_filter(light, 1.0)
    gy, gx = np.gradient(smooth)
    crispness = float(np.percentile(np.hypot(gx, gy)[clear], 90)) / 10.0
    coverage = float(clear.mean())
    richness = (
        entropy * np.sqrt(coverage) * min(1.0, coverage / SMALL_COVERAGE) * clarity
        * (0.4 + 0.6 * min(1.0, separation / SEPARATION_FULL))
    )  # fmt: skip
    discrimination = (min(1.5, separation / SEPARATION_UNIT) + 0.3 * min(1.0, crispness)) * clarity
    return Quality(
        coverage, box, veil, grain, separation, crispness, entropy, clarity,
        float(richness), float(discrimination),
    )  # fmt: skip
