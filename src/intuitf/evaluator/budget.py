"""A spending limit on model calls and money, checked before every call.

A :class:`Budget` may be shared by several judges. A call first *reserves* its place (one call
and an estimate of its price); when the reservation would go past a limit,
:class:`~intuitf.errors.BudgetExhausted` is raised and no request is sent. Reservations count
calls still in flight, so many concurrent calls cannot overshoot the call limit together. The
money limit relies on the caller's estimate of the next call (a judge passes the dearest call it has
seen, or a rough guess from the prompt size before its first answer; with no estimate, the dearest
call this budget has seen), so it is respected up to one call's misestimate.

Across processes the budget is kept by the verdict store (``VerdictCache.spent``): a resumed run
restores the budget's counters from it (:func:`restore_budget`), so the limit covers the whole
run, including the generation that was interrupted and the requests a killed process had under
way. :func:`run_spend` and :func:`with_spend` give a session the exact cost of its run.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from intuitf.errors import BudgetExhausted, IntuitfError
from intuitf.evaluator.types import Cost


@dataclass
class Budget:
    """At most ``max_calls`` paid calls and ``max_usd`` dollars (None = unlimited)."""

    max_calls: int | None = None
    max_usd: float | None = None
    calls: int = 0
    usd: float = 0.0
    _reserved_calls: int = field(default=0, repr=False)
    _reserved_usd: float = field(default=0.0, repr=False)
    _dearest: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        if self.max_calls is not None and self.max_calls < 0:
            raise IntuitfError(
                f"A call budget cannot be negative (got {self.max_calls}).",
                "Give 0 or more calls, or no limit.",
            )
        if self.max_usd is not None and not self.max_usd >= 0:  # also refuses NaN
            raise IntuitfError(
                f"A money budget cannot be negative (got {self.max_usd}).",
                "Give 0 or more dollars, or no limit.",
            )

    def restore(self, spent: Cost, unsettled_calls: int = 0, unsettled_usd: float = 0.0) -> None:
        """Count what the run paid before (a resume): ``spent`` plus requests of unknown fate."""
        self.calls = int(spent.calls) + int(unsettled_calls)
        self.usd = float(spent.usd) + float(unsettled_usd)
        if spent.calls:
            self._dearest = max(self._dearest, spent.usd / spent.calls)

    def reserve(self, estimate_usd: float | None = None) -> float:
        """Claim room for one call; raise BudgetExhausted if it would exceed a limit.

        Returns the amount reserved, to give back to :meth:`settle` or :meth:`release`.
        """
        est = self._dearest if estimate_usd is None else max(0.0, float(estimate_usd))
        if self.max_calls is not None and self.calls + self._reserved_calls + 1 > self.max_calls:
            under_way = f", {self._reserved_calls} more under way" if self._reserved_calls else ""
            raise BudgetExhausted(
                f"The call budget of {self.max_calls} calls is spent ({self.calls} paid"
                f"{under_way}).",
                "Everything judged so far is kept; raise the call limit and resume.",
            )
        if self.max_usd is not None and self.usd + self._reserved_usd + est > self.max_usd + 1e-12:
            raise BudgetExhausted(
                f"The money budget is spent (${self.usd:.4f} of ${self.max_usd:.4f}; the next "
                f"call would cost about ${est:.4f}).",
                "Everything judged so far is kept; raise the money limit and resume.",
            )
        self._reserved_calls += 1
        self._reserved_usd += est
        return est

    def settle(self, reserved: float, usd: float) -> None:
        """Turn a reservation into a paid call costing ``usd``."""
        self._reserved_calls -= 1
        self._reserved_usd -= reserved
        self.calls += 1
        self.usd += usd
        self._dearest = max(self._dearest, usd)

    def release(self, reserved: float) -> None:
        """Give a reservation back (the call was never answered, so nothing was paid)."""
        self._reserved_calls -= 1
        self._reserved_usd -= reserved

    @property
    def remaining_calls(self) -> int | None:
        return None if self.max_calls is None else max(0, self.max_calls - self.calls)

    @property
    def remaining_usd(self) -> float | None:
        return None if self.max_usd is None else max(0.0, self.max_usd - self.usd)


def _store_of(judge: Any, path: str | os.PathLike | None):
    """The judge's verdict store if it is the one at ``path`` (the run's own), else None."""
    cache = getattr(judge, "cache", None)
    if cache is None or not hasattr(cache, "spent"):
        return None
    if path is not None:
        try:
            if Path(cache.path).resolve() != Path(path).resolve():
                return None
        except (OSError, TypeError):
            return None
    return cache


def run_spend(judge: Any, store_path: str | os.PathLike | None) -> Cost | None:
    """Everything the run paid, from its verdict store; None when the judge keeps no store there.

    Requests a killed process had under way count too (calls and estimated dollars; their
    tokens are unknown): the provider may well have charged for them.
    """
    store = _store_of(judge, store_path)
    if store is None:
        return None
    spent = store.spent()
    lost, lost_usd = store.unsettled()
    spent.calls += lost
    spent.usd += lost_usd
    return spent


def with_spend(cost: Cost, spent: Cost | None) -> Cost:
    """``cost`` with its paid calls, tokens and dollars replaced by the store's exact ``spent``."""
    if spent is None:
        return cost
    out = Cost(**cost.__dict__)
    out.calls, out.input_tokens, out.output_tokens = (
        spent.calls,
        spent.input_tokens,
        spent.output_tokens,
    )
    out.usd = spent.usd
    return out


def restore_budget(judge: Any, store_path: str | os.PathLike | None) -> Cost | None:
    """On resume: set the judge's budget to what the run's store says was paid; returns that.

    Requests another process left under way (killed mid-call) count against the budget too.
    """
    store = _store_of(judge, store_path)
    if store is None:
        return None
    spent = store.spent()
    budget = getattr(judge, "budget", None)
    if isinstance(budget, Budget):
        budget.restore(spent, *store.unsettled())
    return spent


def reset_spend(judge: Any, store_path: str | os.PathLike | None) -> None:
    """A new run in this folder: forget the spend of any run that was there before (the
    answers stay, to be reused), and start the judge's budget from nothing."""
    store = _store_of(judge, store_path)
    if store is None:
        return
    store.clear_spend()
    budget = getattr(judge, "budget", None)
    if isinstance(budget, Budget):
        budget.restore(Cost())
