"""Browser tests: Debian's Chromium driven by Playwright against `foil serve` running as a real process on the
paper study (MTurk links, self-selected condition) with the survey tests' bundle of real H.264 clips.

Screenshots of every page go to test-artifacts/browser/. axe-core (installed from npm by `make install` into
.cache/axe) is added to every page to check its accessibility."""

from __future__ import annotations

import pytest

from tests.support.browser import AXE, CHROMIUM, CHROMIUM_ARGS, DESKTOP, study_server
from tests.support.survey import study_text


@pytest.fixture(scope="session")
def server(tmp_path_factory, bundle_dir):
    """One `foil serve` for the browser tests; each test uses its own MTurk worker ids."""
    with study_server(tmp_path_factory.mktemp("browser-server"), bundle_dir, study_text()) as live:
        yield live


@pytest.fixture(scope="session")
def browser():
    """Headless Chromium from Debian with a fresh profile (Playwright launches it on a new user-data dir)."""
    try:
        from playwright import sync_api
    except ImportError:
        pytest.fail("the playwright package is missing: run `make install`")
    if not CHROMIUM.exists():
        pytest.fail(f"{CHROMIUM} is missing: run `make install` (it installs Debian's chromium)")
    if not AXE.exists():
        pytest.fail(f"{AXE} is missing: run `make install` (it installs axe-core from npm)")
    with sync_api.sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


@pytest.fixture
def new_context(browser):
    """Browser contexts (each a separate cookie jar) with axe-core on every page; closed after the test."""
    contexts = []

    def make(viewport: dict = DESKTOP, **options):
        context = browser.new_context(viewport=viewport, accept_downloads=True, **options)
        context.add_init_script(path=str(AXE))  # added by the browser itself: the pages' CSP does not apply
        context.set_default_timeout(15_000)
        contexts.append(context)
        return context

    yield make
    for context in contexts:
        context.close()
