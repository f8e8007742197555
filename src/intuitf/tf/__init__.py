"""Transfer functions: the Gaussian-mixture genome, its lookup table, JSON form and defaults."""

from intuitf.tf.defaults import Material, default_tf, find_materials
from intuitf.tf.gaussian import (
    DEFAULT_GAUSSIANS,
    MAX_GAUSSIANS,
    MIN_GAUSSIANS,
    Gaussian,
    GaussianTF,
)
from intuitf.tf.io import load_tf, save_tf

__all__ = [
    "DEFAULT_GAUSSIANS",
    "MAX_GAUSSIANS",
    "MIN_GAUSSIANS",
    "Gaussian",
    "GaussianTF",
    "Material",
    "default_tf",
    "find_materials",
    "load_tf",
    "save_tf",
]
