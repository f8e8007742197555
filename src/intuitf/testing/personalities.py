"""How a user reaches each of the fake server's personalities: the evaluator flags of
`intuitf optimize` for each, shared by the personality tests and `benchmarks/judge_servers.py`.

``URL`` in a spec stands for the fake server's address; a spec without it names a preset, to
which the address is given with ``--base-url`` (:func:`optimize_flags`).
"""

from __future__ import annotations

#: The evaluator flags per way of reaching a personality (its name, or a variant of it).
SPECS: dict[str, list[str]] = {
    "openai-reasoning": ["--evaluator", "openai:gpt-5.4-mini"],
    "openai-reasoning-by-url": ["--evaluator", "URL#gpt-5.4-mini"],
    "gemini-thinking": ["--evaluator", "gemini:gemini-2.5-flash"],
    # Thoughts (2000 tokens at medium effort) spend a 1024-token budget: asked again with more.
    "gemini-thinking-small-budget": [
        "--evaluator",
        "gemini:gemini-2.5-flash",
        "--max-output-tokens",
        "1024",
        "--reasoning-effort",
        "medium",
    ],  # fmt: skip
    "ollama": ["--evaluator", "ollama"],
    "lmstudio": ["--evaluator", "lmstudio"],
    "vllm-one-image": ["--evaluator", "vllm"],
}


def served(variant: str) -> str:
    """The fake server's personality behind a variant of how it is reached."""
    return variant.removesuffix("-by-url").removesuffix("-small-budget")


def optimize_flags(variant: str, base_url: str) -> list[str]:
    """The evaluator flags of ``variant`` for a fake server at ``base_url``."""
    spec = [s.replace("URL", base_url) for s in SPECS[variant]]
    if not any("URL" in s for s in SPECS[variant]):
        spec += ["--base-url", base_url]
    return spec
