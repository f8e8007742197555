"""intuitf: transfer functions for direct volume rendering, designed from what a person wants.

Public API (everything else may change):
``Volume``, ``load_volume``, ``phantom`` (volumes); ``Gaussian``, ``GaussianTF`` (transfer
functions); ``Camera``, ``VolumeRenderer``, ``SampleCache`` (rendering); ``Intent``, ``Aspect``
(what is wanted); ``Explorer``, ``make_explorer`` (search); ``Session``, ``RunSettings`` (the run
loop). Judges and the tournament are in :mod:`intuitf.evaluator`.
"""

from intuitf.errors import IntuitfError
from intuitf.evaluator.types import Aspect, Intent
from intuitf.explorer import Candidate, Explorer, make_explorer
from intuitf.render import Camera, SampleCache, VolumeRenderer
from intuitf.session import RunSettings, Session
from intuitf.tf import Gaussian, GaussianTF, default_tf, load_tf, save_tf
from intuitf.volume import Volume, load_volume, phantom

__version__ = "0.1.0"

__all__ = [
    "Aspect",
    "Camera",
    "Candidate",
    "Explorer",
    "Gaussian",
    "GaussianTF",
    "Intent",
    "IntuitfError",
    "RunSettings",
    "SampleCache",
    "Session",
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
