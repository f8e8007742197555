"""What model calls cost: USD per million input and output tokens, extendable by the user.

Prices change; the built-in table holds list prices of a few well-known models at the time of
writing and is a convenience, not a bill. A model that is not in the table costs 0 (and a note is
logged once), so local models are free and an unknown cloud model is visibly unpriced.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field

log = logging.getLogger(__name__)

#: model → (USD per 1M input tokens, USD per 1M output tokens).
DEFAULT_PRICES: dict[str, tuple[float, float]] = {
    "gpt-4o": (2.50, 10.00),
    "gpt-4o-mini": (0.15, 0.60),
    "gpt-4.1": (2.00, 8.00),
    "gpt-4.1-mini": (0.40, 1.60),
    "gpt-4.1-nano": (0.10, 0.40),
    "gemini-2.0-flash": (0.10, 0.40),
    "gemini-2.0-flash-001": (0.10, 0.40),
    "gemini-2.5-flash": (0.30, 2.50),
    "gemini-2.5-pro": (1.25, 10.00),
    "claude-sonnet-4": (3.00, 15.00),
}


@dataclass
class PriceTable:
    """Prices by model name; lookups ignore a "vendor/" prefix and match dated variants."""

    prices: dict[str, tuple[float, float]] = field(default_factory=lambda: dict(DEFAULT_PRICES))
    _noted: set[str] = field(default_factory=set, repr=False)

    def with_prices(self, extra: Mapping[str, tuple[float, float] | list[float]]) -> PriceTable:
        """A copy of this table with ``extra`` added (or replacing existing entries)."""
        out = PriceTable(dict(self.prices))
        for model, pair in extra.items():
            inp, outp = (float(x) for x in pair)
            if inp < 0 or outp < 0:
                raise ValueError(f"negative price for {model!r}")
            out.prices[model] = (inp, outp)
        return out

    def lookup(self, model: str) -> tuple[float, float] | None:
        """Prices for ``model``: exact name, then without "vendor/", then the longest prefix."""
        for name in (model, model.rsplit("/", 1)[-1]):
            if name in self.prices:
                return self.prices[name]
        base = model.rsplit("/", 1)[-1]
        best = max((k for k in self.prices if base.startswith(k + "-")), key=len, default=None)
        return self.prices[best] if best else None

    def cost(self, model: str, input_tokens: int, output_tokens: int) -> float:
        """USD for one call; 0 for a model without a price (noted once in the log)."""
        pair = self.lookup(model)
        if pair is None:
            if model not in self._noted:
                self._noted.add(model)
                log.info("No price known for model %r; its calls are counted as free.", model)
            return 0.0
        return (input_tokens * pair[0] + output_tokens * pair[1]) / 1e6
