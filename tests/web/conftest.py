"""Fixtures of the browser tests: a real ``intuitf serve`` on a free loopback port, and Chromium.

The browser is Debian's ``chromium`` (``scripts/test.sh`` installs it when missing), driven by
Playwright's Python API; no browser is ever downloaded. Without a chromium binary the browser
tests are skipped with that reason.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from helpers.browser import CHROMIUM, CHROMIUM_ARGS, skip_reason, start_server, stop_server


@pytest.fixture(scope="module")
def web_server(tmp_path_factory):
    reason = skip_reason()
    if reason:
        pytest.skip(reason)
    server = start_server(tmp_path_factory.mktemp("web"))
    yield server
    stop_server(server)


@pytest.fixture(scope="module")
def browser(web_server):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def shots(tmp_path) -> Path:
    """Where screenshots go: $INTUITF_WEB_SHOTS if set (to look at them), else a temp folder."""
    out = Path(os.environ.get("INTUITF_WEB_SHOTS") or tmp_path / "shots")
    out.mkdir(parents=True, exist_ok=True)
    return out


@pytest.fixture
def page(browser, web_server):
    """A fresh page (1440×900) opened at the printed address; fails the test on page errors."""
    context = browser.new_context(viewport={"width": 1440, "height": 900}, accept_downloads=True)
    pg = context.new_page()
    pg.set_default_timeout(30_000)
    errors: list[str] = []
    console: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.on("console", lambda m: console.append(f"{m.type}: {m.text}") if m.type == "error" else None)
    pg.errors = errors  # type: ignore[attr-defined]
    pg.console_errors = console  # type: ignore[attr-defined]
    pg.goto(web_server.url)
    pg.wait_for_selector("body.ready")
    yield pg
    context.close()
    assert not errors, f"uncaught errors in the page: {errors}"
    csp = [c for c in console if "Content Security Policy" in c]
    assert not csp, f"the page broke its Content-Security-Policy: {csp}"
