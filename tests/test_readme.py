"""The README's promises: the two commands, and the Python API example runs as written."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def _blocks(lang: str) -> list[str]:
    text = README.read_text(encoding="utf-8")
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def test_first_block_holds_the_two_commands_and_ci_runs_the_second():
    first = _blocks("")[0].strip().splitlines()
    assert len(first) == 2
    assert "intuitf" in first[0] and "pytest" not in first[0]
    ci = (README.parent / ".ci" / "run").read_text(encoding="utf-8")
    assert first[1] in ci.splitlines()


def test_python_api_example_runs(capsys):
    (code,) = [b for b in _blocks("python") if "Session.create" in b]
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert out.startswith("completed ")
    assert "(256, 256, 3)" in out
    assert "intuitf.gaussian-tf" in out


def test_service_example_runs(tmp_path, monkeypatch, capsys):
    (code,) = [b for b in _blocks("python") if "RunSpec" in b]
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert "run_ended" in out
    assert "('demo-api', 'completed'), ('demo-api-2', 'completed')" in out
