"""Choosing an explorer by name, and rebuilding one from its saved state."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from intuitf.explorer.base import BaseExplorer
from intuitf.explorer.cmaes import CMAExplorer
from intuitf.explorer.ga import GeneticExplorer
from intuitf.explorer.methods import METHODS as METHODS  # re-exported
from intuitf.explorer.random_search import RandomSearchExplorer
from intuitf.explorer.stages import paper_settings


def make_explorer(method: str = "ga", **kwargs: Any) -> BaseExplorer:
    """An explorer for ``method`` with the keyword arguments of :class:`GeneticExplorer`.

    ``"ga"``: this project's GA; ``"paper-ga"``: the same GA with the authors' settings
    (:func:`paper_settings`); ``"cmaes"``: :class:`CMAExplorer` (also takes ``sigma0``,
    ``stage_sigma``); ``"random"``: :class:`RandomSearchExplorer`.
    """
    if method == "ga":
        return GeneticExplorer(**kwargs)
    if method == "paper-ga":
        kwargs.setdefault("presets", paper_settings())
        return GeneticExplorer(**kwargs)
    if method == "cmaes":
        return CMAExplorer(**kwargs)
    if method == "random":
        return RandomSearchExplorer(**kwargs)
    raise ValueError(f"Unknown explorer method {method!r}; choose one of {METHODS}.")


def explorer_from_state(state: Mapping[str, Any]) -> BaseExplorer:
    """The explorer a :meth:`~BaseExplorer.state_dict` came from, continuing where it was."""
    classes = {c.method: c for c in (GeneticExplorer, CMAExplorer, RandomSearchExplorer)}
    method = state.get("method")
    if method not in classes:
        raise ValueError(f"Unknown explorer method {method!r} in saved state.")
    return classes[method].from_state(state)
