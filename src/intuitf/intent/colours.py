"""Colour names the judge can check and the explorer can paint: name -> sRGB (0-255)."""

from __future__ import annotations

import re

#: Longer names first in the pattern, so "light blue" wins over "blue".
NAMED_COLOURS: dict[str, tuple[int, int, int]] = {
    "bone white": (241, 235, 218),
    "off white": (245, 245, 235),
    "light blue": (150, 190, 240),
    "dark blue": (20, 40, 140),
    "sky blue": (135, 206, 235),
    "navy blue": (20, 30, 110),
    "light green": (144, 238, 144),
    "dark green": (0, 100, 0),
    "dark red": (139, 0, 0),
    "light gray": (200, 200, 200),
    "light grey": (200, 200, 200),
    "dark gray": (80, 80, 80),
    "dark grey": (80, 80, 80),
    "red": (220, 30, 30),
    "crimson": (220, 20, 60),
    "maroon": (128, 0, 0),
    "pink": (255, 160, 190),
    "orange": (255, 140, 0),
    "yellow": (240, 220, 40),
    "yellowish": (230, 215, 90),
    "gold": (212, 175, 55),
    "golden": (212, 175, 55),
    "green": (40, 170, 60),
    "lime": (150, 230, 50),
    "teal": (0, 128, 128),
    "cyan": (0, 200, 220),
    "turquoise": (64, 224, 208),
    "blue": (40, 80, 220),
    "navy": (20, 30, 110),
    "purple": (130, 50, 160),
    "violet": (150, 80, 220),
    "magenta": (220, 40, 200),
    "brown": (130, 80, 40),
    "beige": (225, 205, 165),
    "tan": (210, 180, 140),
    "ivory": (250, 245, 225),
    "white": (245, 245, 245),
    "silver": (192, 192, 198),
    "gray": (128, 128, 128),
    "grey": (128, 128, 128),
    "black": (20, 20, 20),
}

_COLOUR_RE = re.compile(
    r"\b(" + "|".join(re.escape(k) for k in sorted(NAMED_COLOURS, key=len, reverse=True)) + r")\b"
)


def named_colours(text: str) -> list[str]:
    """The colour names in ``text`` that the judge can check, in order, without repeats."""
    found = []
    for m in _COLOUR_RE.finditer(text.lower()):
        if m.group(1) not in found:
            found.append(m.group(1))
    return found


#: Colour names that read as a material in words ("bone white" says "bone"): never given as
#: the name of a colour seen.
NOT_NAMES = ("bone white",)


def colour_word(rgb) -> str:
    """The name of the named colour nearest ``rgb`` (three values in [0, 1]) by ΔE2000: how a
    person would call a stroke's or a reference layer's colour ("red", "light blue")."""
    import numpy as np
    from skimage.color import deltaE_ciede2000, rgb2lab

    lab = rgb2lab(np.clip(np.asarray(rgb, np.float64), 0, 1)[None, None])[0, 0]
    names = [n for n in NAMED_COLOURS if n not in NOT_NAMES]
    labs = rgb2lab(np.array([[NAMED_COLOURS[n] for n in names]], np.float64) / 255.0)[0]
    return names[int(np.argmin(deltaE_ciede2000(labs, lab[None])))]


def rgb_delta_e(a, b) -> float:
    """CIEDE2000 between two sRGB colours (three values in [0, 1] each), as a person tells
    them apart."""
    import numpy as np
    from skimage.color import deltaE_ciede2000, rgb2lab

    lab = rgb2lab(np.stack([np.asarray(a, np.float32), np.asarray(b, np.float32)])[None])[0]
    return float(deltaE_ciede2000(lab[0], lab[1]))
