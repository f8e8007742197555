"""What importing costs: the package and its pure cores load none of the heavy adapters."""

from __future__ import annotations

import subprocess
import sys


def _loaded_after(code: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport sys\nprint(' '.join(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return set(out.split())


def test_import_intuitf_loads_no_heavy_dependency():
    loaded = _loaded_after("import intuitf")
    for heavy in ("numba", "openai", "scipy", "skimage", "matplotlib", "sqlite3", "fastapi"):
        assert heavy not in loaded, heavy


def test_the_evaluators_pure_core_needs_neither_openai_nor_sqlite():
    loaded = _loaded_after(
        "import intuitf.evaluator.tournament, intuitf.evaluator.aspects, "
        "intuitf.evaluator.prompts, intuitf.evaluator.parsing, intuitf.evaluator.metric"
    )
    assert "openai" not in loaded and "sqlite3" not in loaded and "httpx" not in loaded


def test_the_command_line_help_loads_no_kernel_or_model_client():
    loaded = _loaded_after(
        "import sys\nsys.argv = ['intuitf', '--help']\nfrom intuitf.cli.app import app"
    )
    for heavy in ("numba", "openai", "scipy", "skimage", "matplotlib"):
        assert heavy not in loaded, heavy
