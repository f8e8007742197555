"""Every tool's bad inputs (unknown ids, paths outside the roots, links out of them, bad cameras,
huge sizes, malformed TFs and specs) come back as tool errors that say what to do; the server
keeps serving, writes nothing outside its output folder, and never shows an API key."""

from __future__ import annotations

import asyncio
import os

import pytest
from mcp_util import call, call_error, make_config, wait_run_end

from mcp import Client

pytestmark = pytest.mark.timeout(300)

SMALL = {"population": 4, "generations": 1, "image_size": 32, "output_size": 32}


def cases(vid: str, run: str, cand: str, folders) -> list[tuple[str, dict, str]]:
    """(tool, arguments, a piece of the error message)."""
    outside = str(folders["outside"] / "secret_8x8x8_uint8.raw")
    return [
        # volumes
        ("open_volume", {"path": "../outside/secret_8x8x8_uint8.raw"}, "outside the folders"),
        ("open_volume", {"path": outside}, "outside the folders"),
        ("open_volume", {"path": "escape_8x8x8_uint8.raw"}, "outside the folders"),  # a link out
        ("open_volume", {"path": "/etc/passwd"}, "outside the folders"),
        ("open_volume", {"path": "missing_4x4x4_uint8.raw"}, "no volume file"),
        ("open_volume", {"path": "phantom", "max_dim": 1}, "max_dim"),
        ("open_volume", {"path": "phantom", "spacing": [1, -1, 1]}, "spacing"),
        ("open_volume", {"path": ""}, "path"),
        ("describe_volume", {"volume": "nope"}, "open_volume"),
        # pictures
        ("render", {"volume": "nope"}, "no open volume"),
        ("render", {}, "Say what to show"),
        ("render", {"volume": vid, "size": 100000}, "16 to 1024"),
        ("render", {"volume": vid, "size": 0}, "16 to 1024"),
        ("render", {"volume": vid, "camera": {"zoom": -1}}, "zoom must be positive"),
        ("render", {"volume": vid, "camera": {"azimuth": "left"}}, "camera"),
        ("render", {"volume": vid, "camera": {"tilt": 3}}, "Unknown camera field"),
        (
            "render",
            {"volume": vid, "camera": {"position": [1, 2, 3], "focal_point": [1, 2, 3]}},
            "same point",
        ),  # fmt: skip
        (
            "render",
            {
                "volume": vid,
                "camera": {
                    "position": [0, -100, 0],
                    "focal_point": [0, 0, 0],
                    "view_up": [0, 1, 0],
                },
            },
            "parallel",
        ),  # fmt: skip
        (
            "render",
            {"volume": vid, "camera": {"position": [0, 0], "focal_point": [0, 0, 0]}},
            "three finite numbers",
        ),  # fmt: skip
        ("render", {"volume": vid, "camera": {"position": [1e9, 0, 0]}}, "Stand nearer"),
        ("render", {"volume": vid, "background": [2, 0, 0]}, "background"),
        (
            "render",
            {
                "volume": vid,
                "tf": {"gaussians": [{"mean": 2, "width": 0.1, "height": 0.5, "color": [1, 1, 1]}]},
            },
            "mean",
        ),  # fmt: skip
        ("render", {"volume": vid, "tf": {"gaussians": []}}, "1–16 Gaussians"),
        ("render", {"candidate": "../../etc/g000-000"}, "not a candidate id"),
        ("render", {"candidate": f"{run}/g099-000"}, "no candidate"),
        ("render", {"candidate": "nosuchrun/g000-000"}, "no run"),
        ("render", {"candidate": cand, "tf": {"gaussians": []}}, "not both"),
        # transfer functions
        ("get_tf", {"volume": "nope"}, "no open volume"),
        ("get_tf", {"candidate": "bad"}, "not a candidate id"),
        ("set_tf", {"volume": vid, "tf": "not json"}, "not valid JSON"),
        ("set_tf", {"volume": vid, "tf": {"gaussians": [{"mean": 0.5}]}}, "malformed"),
        ("edit_gaussian", {"volume": vid, "index": 99}, "no 99"),
        ("edit_gaussian", {"volume": vid, "index": 0, "width": 5}, "width"),
        ("edit_gaussian", {"volume": vid, "index": 0, "color": [1, 2, 3]}, "color"),
        # runs
        ("start_run", {"volume": "nope"}, "no open volume"),
        ("start_run", {"volume": vid, "settings": {"population": 2}}, "population"),
        ("start_run", {"volume": vid, "settings": {"colour": 1}}, "unknown setting"),
        ("start_run", {"volume": vid, "judge": "nosuch:model"}, "Unknown judge"),
        (
            "start_run",
            {"volume": vid, "intent": {"kind": "image", "reference": outside}},
            "outside the folders",
        ),  # fmt: skip
        (
            "start_run",
            {"volume": vid, "intent": {"kind": "sketch", "sketch": "x.png"}},
            "no sketch picture",
        ),  # fmt: skip
        ("start_run", {"volume": vid, "intent": 5}, "validation error"),
        ("start_run", {"volume": vid, "budget_usd": -1}, "greater than or equal"),
        ("run_status", {"run": "nope"}, "no run"),
        ("run_status", {"run": "../runs"}, "not a run name"),
        ("wait_for_generation", {"run": "nope"}, "no run"),
        ("wait_for_generation", {"run": run, "timeout_s": 10_000}, "less than or equal"),
        ("pause_run", {"run": run}, "not going"),
        ("cancel_run", {"run": run}, "not going"),
        ("continue_run", {"run": run}, "all its generations"),
        ("continue_run", {"run": "nope"}, "no run"),
        ("gallery", {"run": "nope"}, "no run"),
        ("gallery", {"run": run, "size": 5000}, "less than or equal"),
        ("prefer", {"run": run, "better": "g000-000", "worse": "g099-001"}, "Cannot judge"),
        (
            "choose_best",
            {"run": run, "best": "g009-000", "among": ["g009-000", "g009-001"]},
            "Cannot judge",
        ),  # fmt: skip
        ("undo_verdict", {"run": run}, "no verdict"),
        ("features", {"candidate": "nope/g000-000"}, "no run"),
        ("select_feature", {"candidate": cand}, "x and y"),
        ("select_feature", {"candidate": cand, "x": 5000, "y": 3, "size": 64}, "outside"),
        ("select_feature", {"candidate": cand, "index": 42}, "no 42"),
        ("refine", {"candidate": cand, "text": "redder"}, "No feature"),
        ("refine", {"candidate": cand, "text": "redder", "selected": [77]}, "not among them"),
        ("refine", {"candidate": cand, "text": " ", "selected": [0]}, "in words"),
        ("new_query", {"run": run, "intent": None}, "needs an intent"),
        ("new_query", {"run": run, "intent": ""}, "empty"),
        ("new_query", {"run": "nope", "intent": "bones"}, "no run"),
        ("branch", {"run": run, "changes": {"volume": "x"}}, "may change"),
        ("branch", {"run": run, "generation": 42}, "generation 42"),
        ("branch", {"run": run, "candidate": "g099-000"}, "no candidate"),
        # exports
        (
            "export",
            {"candidate": cand, "format": "paraview", "path": "../../escape.json"},
            "outside the folders",
        ),  # fmt: skip
        (
            "export",
            {"candidate": cand, "format": "vtk", "path": "/etc/x.vtk.py"},
            "outside the folders",
        ),  # fmt: skip
        ("export", {"candidate": cand, "format": "obj"}, "paraview"),
        ("export", {"format": "json"}, "Say what to show"),
        ("export", {"candidate": cand, "format": "png", "size": 99999}, "16 to 1024"),
        ("export", {"candidate": cand, "format": "json", "path": "."}, "folder"),
        # unknown tools and arguments
        ("no_such_tool", {}, "Unknown tool"),
        ("render", {"volume": vid, "colour": "red"}, "Extra inputs"),
    ]


def test_every_tool_refuses_bad_input_with_a_message(folders, monkeypatch):
    from intuitf.mcp import build_server

    secret = "sk-test-abcdefghijklmnop1234"
    monkeypatch.setenv("OPENAI_API_KEY", secret)
    server, _ = build_server(make_config(folders))

    async def main():
        async with Client(server) as client:
            vid = (await call(client, "open_volume", path="phantom", max_dim=32))["id"]
            run = (await call(client, "start_run", volume=vid, intent="white bone",
                              judge="metric", settings=SMALL))["run"]  # fmt: skip
            await wait_run_end(client, run)
            cand = (await call(client, "gallery", run=run, k=1, pictures=False))["candidates"][0][
                "id"
            ]
            failures, texts = [], []
            for tool, args, expected in cases(vid, run, cand, folders):
                try:
                    text = await call_error(client, tool, **args)
                except AssertionError as exc:
                    failures.append(str(exc)[:300])
                    continue
                texts.append(text)
                if expected.lower() not in text.lower():
                    failures.append(f"{tool} {args}: {text[:300]!r} lacks {expected!r}")
            # Still serving, and the good path still works.
            assert len((await client.list_tools()).tools) >= 20
            await call(client, "render", volume=vid, size=32)
            # A model judge's key never reaches a result (the fake URL has none: a cloud spec
            # reads it from the environment).
            status = await call(client, "list_runs")
            return failures, texts, status

    failures, texts, status = asyncio.run(main())
    assert not failures, "\n".join(failures)
    assert all(secret not in t for t in texts) and secret not in str(status)
    # Nothing was written outside the output and runs folders.
    assert sorted(os.listdir(folders["outside"])) == ["secret_8x8x8_uint8.raw"]
    assert not (folders["data"].parent / "escape.json").exists()


def test_error_messages_are_scrubbed_of_keys(folders, monkeypatch, caplog):
    """An error that quotes a key (here a judge spec carrying it) shows asterisks instead, in
    the result and in the server's log."""
    import logging

    from intuitf.mcp import build_server

    caplog.set_level(logging.DEBUG)

    secret = "sk-live-0123456789abcdefXYZ"
    monkeypatch.setenv("INTUITF_TEST_API_KEY", secret)
    server, _ = build_server(make_config(folders))

    async def main():
        async with Client(server) as client:
            vid = (await call(client, "open_volume", path="phantom", max_dim=32))["id"]
            return await call_error(client, "start_run", volume=vid, judge=f"nosuch:{secret}")

    text = asyncio.run(main())
    assert secret not in text and "*" * len(secret) in text
    assert "nosuch" in caplog.text  # the failure was logged ...
    assert secret not in caplog.text  # ... without the key


def test_paths_checked_by_roots(tmp_path):
    """The check itself: traversal, links out, relative paths, folders as export targets."""
    from intuitf.mcp.roots import PathRefused, Roots

    data, out, other = tmp_path / "data", tmp_path / "out", tmp_path / "other"
    for d in (data, out, other):
        d.mkdir()
    (other / "x.raw").write_bytes(b"1")
    (data / "in.raw").write_bytes(b"1")
    (data / "link.raw").symlink_to(other / "x.raw")
    (data / "sub").symlink_to(other, target_is_directory=True)
    roots = Roots(data=[data], runs=tmp_path / "runs", out=out)
    assert roots.readable("in.raw") == (data / "in.raw").resolve()
    for bad in ("link.raw", "sub/x.raw", "../other/x.raw", str(other / "x.raw"), "\x00"):
        with pytest.raises(PathRefused):
            roots.readable(bad)
    assert roots.writable("a/b/c.vp") == (out / "a/b/c.vp").resolve()
    assert (out / "a" / "b").is_dir()
    for bad in ("../x.vp", "/tmp/x.vp", ".", "a"):
        with pytest.raises(PathRefused):
            roots.writable(bad)


def test_command_line_mistakes_are_one_message(tmp_path, capsys):
    from intuitf.cli.app import main

    blocker = tmp_path / "file"
    blocker.write_text("x")
    for argv, words in (
        (["mcp", "--data", str(tmp_path / "nope")], "no such folder"),
        (["mcp", "--runs", str(blocker / "runs")], "cannot make this folder"),
        (["mcp", "--device", "tpu"], "auto, cpu or cuda"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
        err = " ".join(capsys.readouterr().err.split())  # rich wraps long lines
        assert words in err and "Traceback" not in err
