"""One browser per test module (tests/web/chromium.py); Playwright's assertions wait as long as its pages do."""

import os

import pytest
from playwright.sync_api import expect, sync_playwright

from tests.web.chromium import CHROMIUM, CHROMIUM_ARGS, WAIT_MS, Chromium

expect.set_options(timeout=WAIT_MS)


@pytest.fixture(scope="module")
def browser():
    if not os.path.exists(CHROMIUM):
        pytest.fail(f"no chromium at {CHROMIUM}: install Debian's package (apt-get install chromium) "
                    "or set DRIFTLAB_CHROMIUM")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield Chromium(b)
        b.close()
