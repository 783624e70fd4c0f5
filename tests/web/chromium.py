"""The browser the view's tests drive: Debian's chromium, headless, through Playwright (no browser download), and
how long a condition in it may take.

Every wait in a browser test is on a condition (a text shown, an attribute set, a console line); WAIT_MS is only its
deadline, set for a 2-core machine running a second copy of the suite beside this one (software WebGL is slow there).
"""

import os
import shutil

CHROMIUM = os.environ.get("DRIFTLAB_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
# Software WebGL without a GPU (docs/reference.md, The view in a headless browser); no background connections on a
# closed network.
CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-dev-shm-usage"]
WAIT_MS = 120_000
WAIT_S = WAIT_MS / 1000


class Chromium:
    """A launched browser whose pages wait up to WAIT_MS for what they are asked (Playwright's default is 30 s)."""

    def __init__(self, browser):
        self._browser = browser

    def new_page(self, **options):
        page = self._browser.new_page(**options)
        page.set_default_timeout(WAIT_MS)
        return page

    def __getattr__(self, name):
        return getattr(self._browser, name)

    def __repr__(self):
        return f"Chromium({self._browser!r})"
