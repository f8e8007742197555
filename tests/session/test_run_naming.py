"""Run folders are named by one rule (RunStore.new_run_dir), whichever front end starts them."""

from __future__ import annotations

import pytest

from intuitf.errors import SessionError
from intuitf.session.store import RunStore


def test_a_new_run_folder_is_named_after_its_base_and_never_taken(tmp_path):
    store = RunStore(tmp_path / "runs")
    first = store.new_run_dir("foot")
    assert first == tmp_path / "runs" / "foot"
    assert not first.exists()  # made by Session.open, which removes it if the run cannot start
    first.mkdir(parents=True)
    assert store.new_run_dir("foot").name == "foot-2"
    (tmp_path / "runs" / "foot-2").mkdir()
    assert store.new_run_dir("foot").name == "foot-3"


@pytest.mark.parametrize(
    ("base", "name"),
    [
        ("CT head (2024)", "CT-head-2024"),
        ("../../etc/passwd", "etc-passwd"),
        ("_hidden", "hidden"),
        ("", "run"),
        ("...", "run"),
        ("x" * 300, "x" * 100),
    ],
)
def test_any_base_becomes_a_plain_folder_name(tmp_path, base, name):
    store = RunStore(tmp_path)
    path = store.new_run_dir(base)
    assert path.parent == tmp_path
    assert path.name == name
    assert store.path_of(path.name) == path  # a name the store itself accepts


def test_a_base_that_is_not_a_name_is_still_refused_by_path_of(tmp_path):
    with pytest.raises(SessionError):
        RunStore(tmp_path).path_of("../x")


def test_the_command_line_names_its_run_folders_by_the_same_rule(tmp_path):
    """`intuitf optimize` without -o: runs/<volume>, then runs/<volume>-2 (as the web does)."""
    import os
    import subprocess
    import sys

    args = [sys.executable, "-m", "intuitf", "optimize", "phantom", "--population", "4",
            "--generations", "1", "--size", "32", "--output-size", "32", "--top", "1"]  # fmt: skip
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    for _ in range(2):
        proc = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, timeout=240,
                              env=env)  # fmt: skip
        assert proc.returncode == 0, proc.stderr
    runs = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert runs == ["phantom", "phantom-2"]
    assert RunStore(tmp_path / "runs").names() == runs  # both are runs the store lists
