"""The Explorer: evolves Gaussian-mixture transfer functions in ask/tell style.

``ask()`` returns the candidates to render; ``tell(ranking)`` takes their ids best first
and builds the next population. :func:`make_explorer` picks the method: the genetic
algorithm (``"ga"``), the authors' GA settings (``"paper-ga"``), CMA-ES (``"cmaes"``) or
random search (``"random"``).
"""

from intuitf.explorer.base import BaseExplorer
from intuitf.explorer.bounds import Bounds, hsl_to_rgb, rgb_to_hsl
from intuitf.explorer.candidate import Candidate
from intuitf.explorer.cmaes import CMAExplorer
from intuitf.explorer.factory import METHODS, explorer_from_state, make_explorer
from intuitf.explorer.ga import Explorer
from intuitf.explorer.genome import decode, encode, near_duplicate
from intuitf.explorer.operators import MutationParams, crossover, elite_count, mutate, roulette
from intuitf.explorer.population import random_tf, seeded_tf
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

__all__ = [
    "CUSTOMIZE",
    "INITIALIZE",
    "METHODS",
    "REFINE",
    "STAGES",
    "BaseExplorer",
    "Bounds",
    "CMAExplorer",
    "Candidate",
    "Decay",
    "Explorer",
    "MutationParams",
    "RandomSearchExplorer",
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
    "rgb_to_hsl",
    "roulette",
    "seeded_tf",
]
