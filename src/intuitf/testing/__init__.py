"""intuitf.testing: tools for tests and benchmarks.

:class:`~intuitf.testing.fake_mllm.FakeMLLMServer` is an OpenAI-compatible multimodal model
server that answers comparisons from an oracle (``python -m intuitf.testing.fake_mllm`` or
``python -m intuitf.testing fake-mllm``); :class:`~intuitf.testing.oracle_judge.OracleJudge`
answers the same way in process, for search experiments with many seeds.
"""

from __future__ import annotations

__all__ = ["FAULT_KINDS", "FakeMLLMServer", "Latency", "OracleJudge"]


def __getattr__(name: str):
    # Imported on first use, so that ``python -m intuitf.testing.fake_mllm`` does not find
    # the module already imported by its package (runpy warns about that).
    if name == "OracleJudge":
        from intuitf.testing.oracle_judge import OracleJudge

        return OracleJudge
    if name in __all__:
        from intuitf.testing import fake_mllm

        return getattr(fake_mllm, name)
    raise AttributeError(f"module 'intuitf.testing' has no attribute {name!r}")
