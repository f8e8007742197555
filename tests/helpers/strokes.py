"""A two-block volume and a sketch over it, for the sketch tests."""

from __future__ import annotations

import numpy as np

from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import Volume


def two_blocks() -> Volume:
    """Two blocks side by side along x: values 0.4 (low x) and 0.8 (high x), in air."""
    d = np.full((40, 40, 40), 0.02, np.float32)
    d[10:30, 10:30, 6:20] = 0.4
    d[10:30, 10:30, 20:34] = 0.8
    return Volume.from_array(d, value_range=(0.0, 1.0))


#: Both blocks shown white: the picture the strokes are drawn over.
BLOCKS_TF = GaussianTF((Gaussian(0.4, 0.03, 0.8, (1, 1, 1)), Gaussian(0.8, 0.03, 0.8, (1, 1, 1))))


def sketch_over(vol: Volume, cam: Camera, size: int = 64) -> np.ndarray:
    """Red strokes over the left block's pixels, blue over the right one's, as seen from cam."""
    r = VolumeRenderer(vol, size=size, shading=False)
    left = r.render_rgba(GaussianTF((BLOCKS_TF.gaussians[0],)), cam)[..., 3] > 0.5
    right = r.render_rgba(GaussianTF((BLOCKS_TF.gaussians[1],)), cam)[..., 3] > 0.5
    sk = np.zeros((size, size, 4), np.uint8)
    row = size // 2
    for mask, colour in ((left & ~right, (220, 30, 30)), (right, (40, 80, 220))):
        band = np.zeros_like(mask)
        band[row - 2 : row + 3] = True
        band &= mask
        sk[band, :3], sk[band, 3] = colour, 255
    return sk
