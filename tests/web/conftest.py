"""The browser the view's tests drive: Debian's chromium, headless, through Playwright (no browser download)."""

import os

import pytest
from playwright.sync_api import sync_playwright

from tests.web.test_view_browser import CHROMIUM, CHROMIUM_ARGS


@pytest.fixture(scope="module")
def browser():
    if not os.path.exists(CHROMIUM):
        pytest.fail(f"no chromium at {CHROMIUM}: install Debian's package (apt-get install chromium) "
                    "or set DRIFTLAB_CHROMIUM")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()
