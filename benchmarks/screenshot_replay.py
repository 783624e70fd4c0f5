"""A screenshot of a standalone replay page (`driftlab episode --html`, or an evaluation's replay.html) in headless
Chromium (Debian's package), taken once the recording has played ``--after-s`` seconds from its start.

    driftlab episode --controller policy:results/sac/policy.npz --seed 1099511627776 --html policy.html \\
        --ghost default --ghost-theta "$(python -c ...)"
    python benchmarks/screenshot_replay.py policy.html docs/screenshots/policy_beside_mpc.png --after-s 8
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from playwright.sync_api import sync_playwright
from screenshots import close_webgl_warning

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.web.chromium import CHROMIUM, CHROMIUM_ARGS  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("html")
    parser.add_argument("png")
    parser.add_argument("--after-s", type=float, default=8.0, help="seconds of the recording played (default 8)")
    args = parser.parse_args()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(Path(args.html).resolve().as_uri())
        page.locator("#driftlab-panel svg").nth(3).wait_for(timeout=60_000)
        close_webgl_warning(page)
        page.wait_for_timeout(int(args.after_s * 1000))
        page.screenshot(path=args.png)
        browser.close()
    print(args.png)


if __name__ == "__main__":
    main()
