"""The browser the view's tests drive: Debian's chromium, headless, through Playwright (no browser download), and
how long a condition in it may take.

Every wait in a browser test is on a condition (a text shown, an attribute set, a console line); WAIT_MS is only its
deadline, set for a 2-core machine running a second copy of the suite beside this one (software WebGL is slow there).
"""

import os
import shutil
import time

from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

CHROMIUM = os.environ.get("DRIFTLAB_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
# Software WebGL without a GPU (docs/reference.md, The view in a headless browser); no background connections on a
# closed network.
CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-dev-shm-usage"]
WAIT_MS = 120_000
# The page draws at most FRAMES_PER_S frames a second: a software-rendered WebGL canvas redrawn at 60 Hz kept ~1.4 of
# the machine's 2 cores busy for the whole browser group (the rest of the suite ran beside it on what was left).
# What the tests check (what is drawn, where the camera goes, what is played) does not depend on the frame rate.
FRAMES_PER_S = 4
_FRAME_CAP = f"""(() => {{
  const draw = window.requestAnimationFrame.bind(window);
  window.requestAnimationFrame = (callback) => setTimeout(() => draw(callback), {1000 // FRAMES_PER_S});
}})();"""
WAIT_S = WAIT_MS / 1000


class Chromium:
    """A launched browser whose pages wait up to WAIT_MS for what they are asked (Playwright's default is 30 s) and
    draw at most FRAMES_PER_S frames a second."""

    def __init__(self, browser):
        self._browser = browser

    def new_page(self, **options):
        page = self._browser.new_page(**options)
        page.add_init_script(_FRAME_CAP)
        page.set_default_timeout(WAIT_MS)
        return page

    def __getattr__(self, name):
        return getattr(self._browser, name)

    def __repr__(self):
        return f"Chromium({self._browser!r})"


def choose_option(page, combobox: str, option: str, *, exact: bool = True) -> None:
    """Open viser's dropdown ``combobox`` and choose its ``option``. The server may redraw the panel while the list is
    open (a job's status changes, the compare panel fills in), which closes it: then it is opened again, until
    WAIT_S has passed. The option gets its click as a DOM event once it is in the list: a pointer click first waits
    for the list to stand still over two animation frames, which a loaded machine at FRAMES_PER_S may not give it
    between two redraws."""
    deadline = time.time() + WAIT_S
    box = page.get_by_role("combobox", name=combobox)
    choice = page.get_by_role("option", name=option, exact=exact).first
    while True:
        if not choice.is_visible():
            box.click()
        try:
            choice.dispatch_event("click", timeout=5_000)
            if not exact or box.input_value(timeout=5_000) == option:
                return
        except PlaywrightTimeoutError:  # closed again before the click
            pass
        if time.time() > deadline:
            raise AssertionError(f"{option!r} could not be chosen in {combobox!r} within {WAIT_S:g} s")


def click_until_shown(clicked, shown) -> None:
    """Click the locator ``clicked`` until the locator ``shown`` is visible, until WAIT_S has passed. For a button
    whose server side reads other inputs (an input's new value and the click travel as separate messages, and on a
    loaded machine the click can be handled before the value has landed), for a ``<details>`` summary clicked while
    the page still lays out its first data (the click can land beside it), and for a viser folder's title, which a
    panel redrawn under it may never let stand still for a pointer click: every other attempt is a DOM click."""
    deadline = time.time() + WAIT_S
    pointer = True
    while True:
        try:
            if pointer:
                clicked.click(timeout=10_000)
            else:
                clicked.dispatch_event("click", timeout=10_000)
            shown.wait_for(timeout=10_000)
            return
        except PlaywrightTimeoutError:
            if time.time() > deadline:
                raise
        pointer = not pointer
