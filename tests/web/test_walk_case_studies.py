"""The paper's three case studies walked in Chromium (tests/web/walk_case_studies.py), with
screenshots in $INTUITF_WEB_SHOTS (tests/web/artifacts/ keeps a set that was looked at)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import walk_case_studies as walk_mod

from helpers.browser import CHROMIUM, CHROMIUM_ARGS, skip_reason

pytestmark = pytest.mark.slow


def test_the_three_case_studies(tmp_path):
    reason = skip_reason()
    if reason:
        pytest.skip(reason)
    if not walk_mod.have_data():
        pytest.skip(f"the case-study volumes are not in {walk_mod.DATA}")
    from playwright.sync_api import sync_playwright

    out = Path(os.environ.get("INTUITF_WEB_SHOTS") or tmp_path / "shots")
    server = walk_mod.Server(tmp_path)
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True,
                                         args=CHROMIUM_ARGS)  # fmt: skip
            seen = walk_mod.walk(browser, server, out)
            browser.close()
    finally:
        server.stop()
    assert not seen["errors"], seen["errors"]
    assert not seen["missing"], f"requests that found nothing: {seen['missing']}"
    assert any(seen["labels"]), seen["labels"]  # features named by the volume's structures
    assert "Ctrl" in seen["hint"]  # the multi-select modifier is named
    assert seen["first_intent"] == "none"  # the first stage, with no words
    assert seen["undo_disabled"] is True
    assert seen["volume_held"] is True
    assert seen["refine_intent"] == "edit"
    assert seen["pot"] and re.search(r"all \d+ that make|the only one", seen["pot_note"])
    assert seen["head_spacing"] == [1, 1, 2]  # set in the volume bar before the head's run
    sx, _, sz = seen["page_spacing"]  # the page's view took it too (a downsampled copy's
    assert 1.9 < sz / sx < 2.1  # voxels are larger, in nearly the same proportion)
    assert seen["export_name"].endswith(".tf.json") and seen["export_menu_open"] is False
    assert seen["deleted"] is True
    assert seen["sketch_intent"] == "sketch"
    # Start waits for the strokes' fit on the tooth: past half a second the page says what
    # it is waiting for.
    if seen["sketch_start_s"] > 2.5:
        assert seen["sketch_start_note"] and "sketch" in seen["sketch_start_note"]
    assert seen["reference_intent"] == "image"
    for name in ("1-bonsai-preview", "1-bonsai-refined", "2-tooth-from-sketch",
                 "3-head-from-foot-reference"):  # fmt: skip
        assert (out / f"{name}.png").stat().st_size > 10_000
