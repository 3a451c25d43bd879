"""Headless Chromium for the tests and benchmarks of ``soro play``: Debian's ``/usr/bin/chromium`` driven by
Playwright (never Playwright's own browser download), a fresh user-data directory per launch.

``browser_page(tmp)`` is a context manager yielding a Playwright page; ``wait_for(page, js, timeout)`` polls a
JavaScript predicate of the page with a generous deadline (the suite runs on loaded machines) and fails with the
page's state when it does not hold.
"""
import contextlib
import shutil
import time
from pathlib import Path

import pytest

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run", "--disable-dev-shm-usage"]


def require_browser():
    """Skip (with the fix) when Playwright or Debian's chromium is missing."""
    pytest.importorskip("playwright", reason="the play extra is missing: run scripts/bootstrap.sh")
    if not Path(CHROMIUM).exists() and not shutil.which("chromium"):
        pytest.skip("Debian's chromium is missing: apt-get install chromium (scripts/bootstrap.sh does)")


@contextlib.contextmanager
def browser_page(user_dir, size=(1100, 760)):
    from playwright.sync_api import sync_playwright
    with sync_playwright() as pw:
        ctx = pw.chromium.launch_persistent_context(str(user_dir), executable_path=CHROMIUM, headless=True,
                                                    args=ARGS, viewport={"width": size[0], "height": size[1]})
        try:
            page = ctx.pages[0] if ctx.pages else ctx.new_page()
            yield page
        finally:
            ctx.close()


def wait_for(page, predicate, timeout=20.0, what=None, poll=0.02):
    """Poll the JavaScript expression ``predicate`` until it is truthy; returns the elapsed time [s]."""
    t0 = time.monotonic()
    while True:
        if page.evaluate(predicate):
            return time.monotonic() - t0
        if time.monotonic() - t0 > timeout:
            state = page.evaluate("JSON.stringify({frame: window.soroPlay && window.soroPlay.frame && "
                                  "{t: soroPlay.frame.t, tip: soroPlay.frame.tip, target: soroPlay.frame.target, "
                                  "mode: soroPlay.frame.mode, message: soroPlay.frame.message}})")
            raise AssertionError(f"{what or predicate} did not hold within {timeout} s; page: {state}")
        time.sleep(poll)
