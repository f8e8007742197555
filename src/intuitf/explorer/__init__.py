"""The Explorer: evolves Gaussian-mixture transfer functions in ask/tell style.

``Explorer`` is the concept (ask, tell, done, best, state_dict); ``ask()`` returns the candidates to render; ``tell(ranking)`` takes their ids best first
and builds the next population. :func:`make_explorer` picks the method: the genetic
algorithm (``"ga"``), the authors' GA settings (``"paper-ga"``), CMA-ES (``"cmaes"``) or
random search (``"random"``).
"""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.explorer.base import BaseExplorer
    from intuitf.explorer.bounds import Bounds, hsl_to_rgb, rgb_to_hsl
    from intuitf.explorer.candidate import Candidate
    from intuitf.explorer.cmaes import CMAExplorer
    from intuitf.explorer.factory import METHODS, explorer_from_state, make_explorer
    from intuitf.explorer.ga import GeneticExplorer
    from intuitf.explorer.genome import decode, encode, near_duplicate
    from intuitf.explorer.operators import MutationParams, crossover, elite_count, mutate, roulette
    from intuitf.explorer.population import random_tf, seeded_tf
    from intuitf.explorer.protocol import Explorer
    from intuitf.explorer.random_search import RandomSearchExplorer
    from intuitf.explorer.stages import (
        CUSTOMIZE,
        INITIALIZE,
        REFINE,
        STAGES,
        Decay,
        StagePreset,
        paper_settings,
    )

_EXPORTS = {
    "BaseExplorer": "intuitf.explorer.base",
    "Bounds": "intuitf.explorer.bounds",
    "hsl_to_rgb": "intuitf.explorer.bounds",
    "rgb_to_hsl": "intuitf.explorer.bounds",
    "Candidate": "intuitf.explorer.candidate",
    "CMAExplorer": "intuitf.explorer.cmaes",
    "METHODS": "intuitf.explorer.factory",
    "explorer_from_state": "intuitf.explorer.factory",
    "make_explorer": "intuitf.explorer.factory",
    "Explorer": "intuitf.explorer.protocol",
    "GeneticExplorer": "intuitf.explorer.ga",
    "PressureSchedule": "intuitf.explorer.fitness",
    "rank_fitness": "intuitf.explorer.fitness",
    "decode": "intuitf.explorer.genome",
    "encode": "intuitf.explorer.genome",
    "near_duplicate": "intuitf.explorer.genome",
    "MutationParams": "intuitf.explorer.operators",
    "crossover": "intuitf.explorer.operators",
    "elite_count": "intuitf.explorer.operators",
    "mutate": "intuitf.explorer.operators",
    "roulette": "intuitf.explorer.operators",
    "random_tf": "intuitf.explorer.population",
    "seeded_tf": "intuitf.explorer.population",
    "RandomSearchExplorer": "intuitf.explorer.random_search",
    "CUSTOMIZE": "intuitf.explorer.stages",
    "INITIALIZE": "intuitf.explorer.stages",
    "REFINE": "intuitf.explorer.stages",
    "STAGES": "intuitf.explorer.stages",
    "Decay": "intuitf.explorer.stages",
    "StagePreset": "intuitf.explorer.stages",
    "paper_settings": "intuitf.explorer.stages",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "BaseExplorer",
    "Bounds",
    "CMAExplorer",
    "CUSTOMIZE",
    "Candidate",
    "Decay",
    "Explorer",
    "GeneticExplorer",
    "PressureSchedule",
    "INITIALIZE",
    "METHODS",
    "MutationParams",
    "REFINE",
    "RandomSearchExplorer",
    "STAGES",
    "StagePreset",
    "crossover",
    "decode",
    "elite_count",
    "encode",
    "explorer_from_state",
    "hsl_to_rgb",
    "make_explorer",
    "mutate",
    "near_duplicate",
    "paper_settings",
    "random_tf",
    "rank_fitness",
    "rgb_to_hsl",
    "roulette",
    "seeded_tf",
]
