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
        "import intuitf.evaluator.tournament, intuitf.intent.aspects, "
        "intuitf.evaluator.prompts, intuitf.evaluator.parsing, intuitf.evaluator.metric"
    )
    assert "openai" not in loaded and "sqlite3" not in loaded and "httpx" not in loaded


def test_the_command_line_help_loads_no_kernel_or_model_client():
    loaded = _loaded_after(
        "import sys\nsys.argv = ['intuitf', '--help']\nfrom intuitf.cli.app import app"
    )
    for heavy in ("numba", "openai", "scipy", "skimage", "matplotlib"):
        assert heavy not in loaded, heavy


def test_every_public_name_is_the_object_not_a_submodule_of_the_same_name():
    # Importing a submodule binds it to its package; a public name that is also a submodule
    # name (intuitf.volume.phantom) must still be the function.
    code = (
        "import importlib, pkgutil, types, intuitf\n"
        "for m in pkgutil.walk_packages(intuitf.__path__, 'intuitf.'):\n"
        "    if any(p in m.name for p in ('.web', '.cli', 'testing', 'batch', '__main__')):\n"
        "        continue\n"
        "    importlib.import_module(m.name)\n"
        "bad = []\n"
        "for pkg in ['intuitf', 'intuitf.render', 'intuitf.explorer', 'intuitf.tf',\n"
        "            'intuitf.volume', 'intuitf.evaluator', 'intuitf.session']:\n"
        "    mod = importlib.import_module(pkg)\n"
        "    bad += [f'{pkg}.{n}' for n in mod.__all__\n"
        "            if isinstance(getattr(mod, n), types.ModuleType)]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
