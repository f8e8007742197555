"""A spending limit on model calls and money, checked before every call.

A :class:`Budget` may be shared by several judges. A call first *reserves* its place (one call
and an estimate of its price); when the reservation would go past a limit,
:class:`~intuitf.errors.BudgetExhausted` is raised and no request is sent. Reservations count
calls still in flight, so many concurrent calls cannot overshoot the call limit together. The
money limit relies on the caller's estimate of the next call (a judge passes the dearest call it has
seen, or a rough guess from the prompt size before its first answer; with no estimate, the dearest
call this budget has seen), so it is respected up to one call's misestimate.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from intuitf.errors import BudgetExhausted


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

    def reserve(self, estimate_usd: float | None = None) -> float:
        """Claim room for one call; raise BudgetExhausted if it would exceed a limit.

        Returns the amount reserved, to give back to :meth:`settle` or :meth:`release`.
        """
        est = self._dearest if estimate_usd is None else max(0.0, float(estimate_usd))
        if self.max_calls is not None and self.calls + self._reserved_calls + 1 > self.max_calls:
            raise BudgetExhausted(
                f"The call budget is spent ({self.calls} of {self.max_calls} calls).",
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
