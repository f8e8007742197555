"""The Explorer: evolves Gaussian-mixture transfer functions in ask/tell style.

``ask()`` returns the candidates to render; ``tell(ranking)`` takes their ids best first
and builds the next population. :func:`make_explorer` picks the method: the genetic
algorithm (``"ga"``), the authors' GA settings (``"paper-ga"``), CMA-ES (``"cmaes"``) or
random search (``"random"``).
"""

from intuitf.explorer.base import BaseExplorer
from intuitf.explorer.bounds import Bounds, hsl_to_rgb, rgb_to_hsl
from intuitf.explorer.candidate import Candidate
from intuitf.explorer.ga import Explorer
from intuitf.explorer.genome import decode, encode, near_duplicate
from intuitf.explorer.operators import MutationParams, crossover, elite_count, mutate, roulette
from intuitf.explorer.population import random_tf, seeded_tf
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
    "REFINE",
    "STAGES",
    "BaseExplorer",
    "Bounds",
    "Candidate",
    "Decay",
    "Explorer",
    "MutationParams",
    "StagePreset",
    "crossover",
    "decode",
    "elite_count",
    "encode",
    "hsl_to_rgb",
    "mutate",
    "near_duplicate",
    "paper_settings",
    "random_tf",
    "rgb_to_hsl",
    "roulette",
    "seeded_tf",
]
