"""intuitf: transfer functions for direct volume rendering, designed from what a person wants.

Public API (everything else may change):
``Volume``, ``load_volume``, ``phantom`` (volumes); ``Gaussian``, ``GaussianTF`` (transfer
functions); ``Camera``, ``VolumeRenderer``, ``SampleCache`` (rendering); ``Intent``, ``Aspect``
(what is wanted); ``Explorer``, ``make_explorer`` (search); ``Session``, ``RunSettings`` (the run
loop). Judges and the tournament are in :mod:`intuitf.evaluator`.
"""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.errors import IntuitfError
    from intuitf.evaluator.types import Aspect, Intent
    from intuitf.explorer import Candidate, Explorer, make_explorer
    from intuitf.render import Camera, SampleCache, VolumeRenderer
    from intuitf.session import RunSettings, Session
    from intuitf.tf import Gaussian, GaussianTF, default_tf, load_tf, save_tf
    from intuitf.volume import Volume, load_volume, phantom

_EXPORTS = {
    "IntuitfError": "intuitf.errors",
    "Aspect": "intuitf.evaluator.types",
    "Intent": "intuitf.evaluator.types",
    "Candidate": "intuitf.explorer",
    "Explorer": "intuitf.explorer",
    "make_explorer": "intuitf.explorer",
    "Camera": "intuitf.render",
    "SampleCache": "intuitf.render",
    "VolumeRenderer": "intuitf.render",
    "RunSettings": "intuitf.session",
    "Session": "intuitf.session",
    "Gaussian": "intuitf.tf",
    "GaussianTF": "intuitf.tf",
    "default_tf": "intuitf.tf",
    "load_tf": "intuitf.tf",
    "save_tf": "intuitf.tf",
    "Volume": "intuitf.volume",
    "load_volume": "intuitf.volume",
    "phantom": "intuitf.volume",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

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
