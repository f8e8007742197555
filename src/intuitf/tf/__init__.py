"""Transfer functions: the Gaussian-mixture genome, its lookup table, JSON form and defaults."""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.tf.defaults import Material, default_tf, find_materials
    from intuitf.tf.gaussian import (
        DEFAULT_GAUSSIANS,
        MAX_GAUSSIANS,
        MIN_GAUSSIANS,
        Gaussian,
        GaussianTF,
    )
    from intuitf.tf.io import load_tf, save_tf

_EXPORTS = {
    "Material": "intuitf.tf.defaults",
    "default_tf": "intuitf.tf.defaults",
    "find_materials": "intuitf.tf.defaults",
    "DEFAULT_GAUSSIANS": "intuitf.tf.gaussian",
    "MAX_GAUSSIANS": "intuitf.tf.gaussian",
    "MIN_GAUSSIANS": "intuitf.tf.gaussian",
    "Gaussian": "intuitf.tf.gaussian",
    "GaussianTF": "intuitf.tf.gaussian",
    "load_tf": "intuitf.tf.io",
    "save_tf": "intuitf.tf.io",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "DEFAULT_GAUSSIANS",
    "Gaussian",
    "GaussianTF",
    "MAX_GAUSSIANS",
    "MIN_GAUSSIANS",
    "Material",
    "default_tf",
    "find_materials",
    "load_tf",
    "save_tf",
]
