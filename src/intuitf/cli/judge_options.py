"""The model judge's command-line options that ``optimize``, ``serve`` and ``batch`` share.

Each command declares them with these aliases and turns them into judge options (the keyword
arguments of :class:`~intuitf.evaluator.mllm.MLLMJudge`, kept in the run's spec) with
:func:`judge_options`. Options left out fall back to ``[judge]`` in the config file, then to the
model's profile (:mod:`intuitf.evaluator.profiles`).
"""

from __future__ import annotations

from typing import Annotated, Any

import typer

from intuitf.errors import IntuitfError

_PANEL = "Model judge options"

MaxConcurrencyOpt = Annotated[
    int | None,
    typer.Option(
        "--max-concurrency",
        min=1,
        help="At most this many judge requests in flight (default: start at the server's "
        "profile, 1 for Ollama and LM Studio, and grow while answers come back in time).",
        rich_help_panel=_PANEL,
    ),
]
MaxOutputTokensOpt = Annotated[
    int | None,
    typer.Option(
        "--max-output-tokens",
        min=1,
        help="Token budget of one answer, reasoning included (default 2048, 4096 for "
        "reasoning models; raised when thoughts spend it).",
        rich_help_panel=_PANEL,
    ),
]
ReasoningEffortOpt = Annotated[
    str | None,
    typer.Option(
        "--reasoning-effort",
        metavar="none|minimal|low|medium|high|default",
        help="How much a reasoning model may think per answer (default low; 'default' sends "
        "nothing: the model's own default).",
        rich_help_panel=_PANEL,
    ),
]
PriceOpt = Annotated[
    str | None,
    typer.Option(
        "--price",
        metavar="IN,OUT",
        help="The model's price, USD per million input and output tokens, e.g. 0.75,4.50 "
        "(needed with --budget-usd when intuitf does not know it).",
        rich_help_panel=_PANEL,
    ),
]
UnpricedOpt = Annotated[
    bool,
    typer.Option(
        "--unpriced",
        help="Run a model of unknown price with --budget-usd anyway (its calls count as free).",
        rich_help_panel=_PANEL,
    ),
]

EFFORTS = ("none", "minimal", "low", "medium", "high", "xhigh", "default")


def parse_price(text: str | None) -> tuple[float, float] | None:
    """``"0.75,4.50"`` as (0.75, 4.5); IntuitfError for anything else."""
    if text is None:
        return None
    try:
        parts = [float(x) for x in text.replace(" ", "").split(",")]
    except ValueError:
        parts = []
    if len(parts) != 2 or min(parts) < 0:
        raise IntuitfError(
            f"--price {text!r} is not two prices.",
            "Give USD per million input tokens and per million output tokens: --price 0.75,4.50.",
        )
    return parts[0], parts[1]


def judge_options(
    max_concurrency: int | None = None,
    max_output_tokens: int | None = None,
    reasoning_effort: str | None = None,
    price: str | None = None,
    unpriced: bool = False,
) -> dict[str, Any]:
    """The judge options the command line gave (only those given)."""
    out: dict[str, Any] = {}
    if max_concurrency is not None:
        out["max_concurrency"] = int(max_concurrency)
    if max_output_tokens is not None:
        out["max_output_tokens"] = int(max_output_tokens)
    if reasoning_effort is not None:
        effort = reasoning_effort.strip().lower()
        if effort not in EFFORTS:
            raise IntuitfError(
                f"--reasoning-effort {reasoning_effort!r} is not a reasoning effort.",
                f"Use one of: {', '.join(EFFORTS)}.",
            )
        out["reasoning_effort"] = effort
    parsed = parse_price(price)
    if parsed is not None:
        out["price"] = list(parsed)
    if unpriced:
        out["unpriced"] = True
    return out
