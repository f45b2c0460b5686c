"""Headless Chromium for the browser tests (test_page_browser, test_study_browser,
test_page_injection): Debian's `chromium` driven by `playwright` with the project's
launch arguments, skipped with the reason when either is missing (.ci/run installs
both), and pages that record console errors and refuse every request that is not
a local file, as on a laptop offline.
"""
from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
#: The developers' guide's arguments: no sandbox, GPU, background networking, updates or sync.
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]
VIEWPORT = {"width": 1280, "height": 800}
#: Schemes a page may load; anything else (http, https, ws ...) is refused and recorded.
LOCAL = ("file:", "data:", "blob:")


@contextmanager
def chromium():
    """A launched headless Chromium (closed on exit); pytest.skip, saying why and how to
    install it, when playwright or the browser is missing."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("playwright is not installed (pip install -e '.[test,browser]'); .ci/run installs it")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install -y chromium); .ci/run installs it"
                    + (f": {os.environ['LGP_NO_BROWSER']}" if os.environ.get("LGP_NO_BROWSER") else ""))
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            yield browser
        finally:
            browser.close()


def offline_page(browser, clock: bool = False, **options):
    """(page, console errors, refused urls): a new page (its own context; `options`
    are playwright's context options, viewport VIEWPORT unless given) that records
    console errors and uncaught exceptions and refuses every non-local request.
    With `clock`, the page's clock is installed at 0 (page.clock). Not navigated yet."""
    page = browser.new_page(**{"viewport": VIEWPORT, **options})
    errors, refused = [], []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))

    def route(r):
        if r.request.url.startswith(LOCAL):
            r.continue_()
        else:
            refused.append(r.request.url)
            r.abort()

    page.route("**/*", route)
    if clock:
        page.clock.install(time=0)
    return page, errors, refused


def keep_screenshot(page, name: str, **kw) -> None:
    """Save a screenshot of `page` as LGP_SCREENSHOTS/name when that variable is set."""
    if os.environ.get("LGP_SCREENSHOTS"):
        Path(os.environ["LGP_SCREENSHOTS"]).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(os.environ["LGP_SCREENSHOTS"]) / name), **kw)
