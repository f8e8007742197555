"""intuitf: transfer functions for direct volume rendering, designed from what a person wants.

Public API (everything else may change):
``Volume``, ``load_volume``, ``phantom`` (volumes); ``Gaussian``, ``GaussianTF`` (transfer
functions); ``Camera``, ``VolumeRenderer``, ``SampleCache`` (rendering); judges, the tournament
and the Explorer live in their packages and are re-exported here as they land.
"""

from intuitf.errors import IntuitfError
from intuitf.explorer import Candidate, Explorer, make_explorer
from intuitf.render import Camera, SampleCache, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF, default_tf, load_tf, save_tf
from intuitf.volume import Volume, load_volume, phantom

__version__ = "0.1.0"

__all__ = [
    "Camera",
    "Candidate",
    "Explorer",
    "Gaussian",
    "GaussianTF",
    "IntuitfError",
    "SampleCache",
    "Volume",
    "VolumeRenderer",
    "__version__",
    "default_tf",
    "load_tf",
    "load_volume",
    "make_explorer",
    "phantom",
    "save_tf",
]
