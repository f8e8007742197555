"""intuitf.testing: tools for tests and benchmarks.

:class:`~intuitf.testing.fake_mllm.FakeMLLMServer` is an OpenAI-compatible multimodal model
server that answers comparisons from an oracle (``python -m intuitf.testing fake-mllm``).
"""

from intuitf.testing.fake_mllm import FAULT_KINDS as FAULT_KINDS
from intuitf.testing.fake_mllm import FakeMLLMServer as FakeMLLMServer
from intuitf.testing.fake_mllm import Latency as Latency
