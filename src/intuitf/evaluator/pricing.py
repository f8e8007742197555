"""What model calls cost: USD per million input and output tokens, extendable by the user.

Prices change; the built-in table (:data:`intuitf.evaluator.profiles.PRICES`, with the date it
was checked) holds list prices of current models and is a convenience, not a bill: ``[prices]``
in the config file and the judge's ``price`` option override it, and a server that reports the
price of each call (OpenRouter's ``usage.cost``) is believed over the table. A model that is not
in the table costs 0 (and a note is logged once), so local models are free and an unknown cloud
model is visibly unpriced; a money budget refuses such a model unless its price is given.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from intuitf.evaluator.profiles import PRICES, base_name

log = logging.getLogger(__name__)

#: model → (USD per 1M input tokens, USD per 1M output tokens).
DEFAULT_PRICES: dict[str, tuple[float, float]] = dict(PRICES)

#: What may follow a priced name in a variant of the same model at the same price: a date
#: ("-2024-08-06", "-0125", "-09-2025"), "-latest", "-preview..." or "-exp...". "-lite", "-mini"
#: and the like are other models with other prices.
_VARIANT = re.compile(r"^(\d{4}(-\d{2}-\d{2})?|\d{2}-\d{4}|\d{3,}|latest|(preview|exp)(-[\w-]*)?)$")


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
        """Prices for ``model``: exact name, then without "vendor/" (and ":variant"), then a
        dated or preview variant of a priced name (``gpt-4o-2024-08-06`` costs as ``gpt-4o``;
        ``gemini-2.5-flash-lite`` is not ``gemini-2.5-flash``)."""
        for name in (model, model.rsplit("/", 1)[-1], base_name(model)):
            if name in self.prices:
                return self.prices[name]
        base = base_name(model)
        best = max(
            (
                k
                for k in self.prices
                if base.startswith(k + "-") and _VARIANT.match(base[len(k) + 1 :])
            ),
            key=len,
            default=None,
        )
        return self.prices[best] if best else None

    def known(self, model: str) -> bool:
        """Whether ``model`` has a price here."""
        return self.lookup(model) is not None

    def cost(self, model: str, input_tokens: int, output_tokens: int) -> float:
        """USD for one call; 0 for a model without a price (noted once in the log)."""
        pair = self.lookup(model)
        if pair is None:
            if model not in self._noted:
                self._noted.add(model)
                log.info("No price known for model %r; its calls are counted as free.", model)
            return 0.0
        return (input_tokens * pair[0] + output_tokens * pair[1]) / 1e6
