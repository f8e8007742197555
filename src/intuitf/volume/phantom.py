"""A procedural CT-like head phantom, so that everything runs without any data file.

The phantom is a stylised head and neck in 8-bit "CT" units: air around it, a skin layer over
subcutaneous fat, soft tissue (brain) with a folded texture, a skull with eye sockets, eyeballs,
a nasal air cavity, a jaw arch carrying teeth of dense enamel, and a cervical spine of vertebrae
and discs around an air-filled trachea. Each material has its own grey level, so the histogram
shows distinct peaks that a transfer function can pick apart. Edges are softened like a
scanner's point-spread function, and smooth texture and noise make it look measured.
"""

from __future__ import annotations

import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.volume import Volume

#: Grey levels (uint8) of the phantom's materials.
MATERIALS = {
    "air": 4.0,
    "fat": 62.0,
    "fluid": 80.0,
    "soft tissue": 104.0,
    "skin": 122.0,
    "disc": 132.0,
    "bone": 205.0,
    "enamel": 245.0,
}


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, ...], sigma: float) -> np.ndarray:
    """Zero-mean, unit-variance noise correlated over about ``sigma`` voxels."""
    from scipy import ndimage

    factor = max(1.0, sigma / 2.0)
    if factor > 1.5:  # broad noise: make it on a coarse grid and interpolate (much faster)
        small = tuple(max(4, int(np.ceil(s / factor))) for s in shape)
        f = ndimage.gaussian_filter(rng.standard_normal(small).astype(np.float32), 2.0, mode="wrap")
        f = ndimage.zoom(f, [a / b for a, b in zip(shape, small, strict=True)], order=1)
    else:
        f = ndimage.gaussian_filter(
            rng.standard_normal(shape).astype(np.float32), sigma, mode="wrap"
        )
    return (f - f.mean()) / max(float(f.std()), 1e-6)


def _ellipsoid(x, y, z, c, r) -> np.ndarray:
    """Approximate signed distance (negative inside) to an axis-aligned ellipsoid."""
    q = np.sqrt(((x - c[0]) / r[0]) ** 2 + ((y - c[1]) / r[1]) ** 2 + ((z - c[2]) / r[2]) ** 2)
    return (q - 1.0) * min(r)


def _smooth_union(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def phantom_array(size: int = 96, seed: int = 0) -> np.ndarray:
    """The phantom as a uint8 array ``[z, y, x]`` of ``size`` voxels per side (z up, y front)."""
    from scipy import ndimage

    n = int(size)
    if n < 16 or n > 1024:
        raise VolumeError(
            f"phantom size must be between 16 and 1024 voxels, got {size}.", "Use e.g. 96."
        )
    rng = np.random.default_rng(seed)
    ax = np.linspace(-1.0, 1.0, n, dtype=np.float32)
    z, y, x = np.meshgrid(ax, ax, ax, indexing="ij", sparse=True)
    # A low-frequency warp makes the outline organic rather than a perfect ellipsoid.
    warp = 0.035 * _smooth_noise(rng, (n, n, n), sigma=n / 8)

    head = _ellipsoid(x, y, z, (0.0, 0.0, 0.22), (0.60, 0.72, 0.66)) + warp
    neck = np.maximum(
        np.sqrt((x / 0.30) ** 2 + ((y + 0.08) / 0.28) ** 2) * 0.28 - 0.28, -(z + 0.95)
    )  # cylinder capped at the bottom
    nose = _ellipsoid(x, y, z, (0.0, 0.70, 0.05), (0.09, 0.14, 0.16))
    body = _smooth_union(_smooth_union(head, neck, 0.12), nose, 0.05)

    vol = np.full(body.shape, MATERIALS["air"], dtype=np.float32)
    inside = body < 0
    vol[inside] = MATERIALS["soft tissue"]
    vol[(body < -0.025) & (body >= -0.075)] = MATERIALS["fat"]
    vol[(body >= -0.025) & inside] = MATERIALS["skin"]

    # Skull: a shell under the scalp; the brain inside gets folded texture.
    skull_in = _ellipsoid(x, y, z, (0.0, -0.02, 0.26), (0.47, 0.58, 0.52)) + warp
    skull_out = skull_in - 0.07
    skull = (skull_out < 0) & (skull_in >= 0) & (z > -0.22)
    brain = skull_in < 0
    folds = np.abs(_smooth_noise(rng, (n, n, n), sigma=n / 40))
    vol[brain] = MATERIALS["soft tissue"] - 6.0 + 12.0 * folds[brain]
    vol[skull] = MATERIALS["bone"]

    # Eye sockets cut through the skull, each holding a fluid-filled eyeball.
    for sx in (-0.21, 0.21):
        socket = _ellipsoid(x, y, z, (sx, 0.50, 0.22), (0.14, 0.16, 0.12))
        vol[socket < 0] = MATERIALS["fat"]
        eye = _ellipsoid(x, y, z, (sx, 0.54, 0.22), (0.09, 0.09, 0.09))
        vol[eye < 0] = MATERIALS["fluid"]

    # Nasal cavity and sinus: air inside the face.
    nasal = _ellipsoid(x, y, z, (0.0, 0.46, 0.02), (0.07, 0.20, 0.13))
    sinus = _ellipsoid(x, y, z, (0.0, 0.30, 0.12), (0.16, 0.10, 0.07))
    vol[(nasal < 0) | (sinus < 0)] = MATERIALS["air"]

    # Jaw: a horseshoe-shaped arch of bone in front, with a row of teeth on top.
    r_arch = np.sqrt(x**2 + ((y - 0.05) / 1.15) ** 2)
    arch = (np.abs(r_arch - 0.40) < 0.055) & (y > 0.02) & (np.abs(z + 0.22) < 0.07)
    vol[arch] = MATERIALS["bone"]
    for ang in np.linspace(0.15 * np.pi, 0.85 * np.pi, 10):
        tx, ty = 0.40 * np.cos(ang), 0.05 + 1.15 * 0.40 * np.sin(ang)
        tooth = _ellipsoid(x, y, z, (tx, ty, -0.09), (0.055, 0.05, 0.08))
        vol[tooth < 0] = MATERIALS["enamel"]

    # Cervical spine: vertebral bodies with discs between them, behind the trachea.
    in_column = np.sqrt(x**2 + ((y + 0.18) / 0.9) ** 2) < 0.11
    phase = np.mod(z + 1.0, 0.13)
    column = in_column & (z < -0.18) & (z > -0.97)
    vol[column & (phase < 0.095)] = MATERIALS["bone"]
    vol[column & (phase >= 0.095)] = MATERIALS["disc"]
    trachea = (np.sqrt(x**2 + ((y - 0.06) / 1.2) ** 2) < 0.06) & (z < -0.25) & (z > -0.97)
    vol[trachea] = MATERIALS["air"]

    # Scanner blur (partial volume at edges), smooth tissue texture, then noise.
    vol = ndimage.gaussian_filter(vol, 0.8)
    body_mask = ndimage.gaussian_filter(inside.astype(np.float32), 1.0)
    vol += 5.0 * _smooth_noise(rng, vol.shape, sigma=2.0) * body_mask
    vol += rng.normal(0.0, 3.0, vol.shape).astype(np.float32)
    return np.clip(np.rint(vol), 0, 255).astype(np.uint8)


def phantom(size: int = 96, seed: int = 0) -> Volume:
    """The built-in CT-like head phantom as a :class:`Volume` named ``"phantom"`` (uint8 units).

    The same ``size`` and ``seed`` always give the same volume.
    """
    vol = Volume.from_array(phantom_array(size, seed), name="phantom", source="builtin:phantom")
    vol.notes.append(f"Procedural head phantom, {size}^3 voxels, seed {seed}.")
    return vol
