"""The screenshots in docs/screenshots/, taken in headless Chromium (Debian's package) against a real server:

- search_space.png: the dashboard's search-space panel of a 60-evaluation job;
- chase_paused_flick.png: the 3D view's chase camera, paused at the job's best episode's first flick;
- replay.png: the standalone HTML replay with its caption panel and state plots.

    python benchmarks/screenshots.py [--out docs/screenshots] [--iterations 60]

The job is tuned by the server it shows (seed 0, 1 episode per evaluation so that it takes minutes, not tens of
minutes); every wait is for a condition on the page or the API, not a fixed time.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import httpx
from playwright.sync_api import sync_playwright
from served import served

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.web.chromium import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

# The sideslip changes sign ~0.45 s after a trigger and is near its new value after ~1.1 s (docs/results.md): at
# 0.9 s the car is deep in the flick, at an angle to its path.
FLICK_AFTER_TRIGGER_S = 0.9


def close_webgl_warning(page) -> None:
    """viser's notice that WebGL runs in software (no GPU here): closed so that it does not cover the scene."""
    notice = page.locator("[role=alert]", has_text="Software WebGL")
    notice.wait_for(timeout=30_000)
    notice.locator("button").first.click()
    notice.wait_for(state="detached", timeout=10_000)


def tune(url: str, iterations: int) -> dict:
    job = httpx.post(f"{url}/api/jobs", json={"name": "screenshots", "iterations": iterations, "seed_points": 12,
                                              "robust_samples": 1, "confirm_samples": 0}).json()
    while (job := httpx.get(f"{url}/api/jobs/{job['id']}").json())["status"] != "finished":
        print(f"  {job['n_done']} / {iterations} evaluations", file=sys.stderr, flush=True)
        time.sleep(5)
    return job


def search_space(browser, url: str, job: dict, out: Path) -> None:
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(f"{url}/dashboard/?job={job['id']}")
    page.wait_for_function("n => Number(document.querySelector('#search-space')?.dataset.nEvaluations) === n",
                           arg=job["n_done"], timeout=120_000)
    page.locator("#job-panel").screenshot(path=out / "search_space.png")
    page.close()


def chase_paused(browser, url: str, job: dict, out: Path) -> None:
    best = httpx.get(f"{url}/api/jobs/{job['id']}/best").json()
    flick_s = round(best["trigger_points"][0]["t_s"] + FLICK_AFTER_TRIGGER_S, 1)
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    connected = []
    page.on("console", lambda m: connected.append(m.text) if "Connected!" in m.text else None)
    page.goto(f"{url}/viser/")
    page.get_by_role("button", name="Play best").wait_for(timeout=60_000)
    close_webgl_warning(page)
    page.get_by_role("button", name="Play best").click()
    page.get_by_text("Rewatch", exact=False).first.wait_for(timeout=60_000)
    page.get_by_role("button", name="Pause").click()
    page.get_by_role("button", name="Play", exact=True).wait_for(timeout=10_000)
    page.get_by_role("checkbox", name="Chase camera").check()
    time_slider = page.get_by_role("slider").nth(1)  # playback speed, then time
    time_slider.focus()
    time_slider.press("Home")
    for _ in range(int(round(flick_s / 0.1))):
        time_slider.press("ArrowRight")
    page.get_by_text(f"t {flick_s:5.1f} /".strip(), exact=False).first.wait_for(timeout=30_000)
    page.wait_for_function("() => document.querySelector('canvas') !== null")
    page.wait_for_timeout(1500)  # the camera's move is animated by the client; nothing on the page says it ended
    page.screenshot(path=out / "chase_paused_flick.png")
    page.close()


def replay(browser, url: str, job: dict, out: Path) -> None:
    html = httpx.get(f"{url}/api/evaluations/{job['best']['id']}/replay.html").text
    with tempfile.NamedTemporaryFile("w", suffix=".html", delete=False) as f:
        f.write(html)
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    loaded = []
    page.on("console", lambda m: loaded.append(m.text))
    page.goto(Path(f.name).as_uri())
    page.locator("#driftlab-panel svg").nth(3).wait_for(timeout=30_000)
    close_webgl_warning(page)
    page.wait_for_timeout(8000)  # the recording plays from its start: a few seconds of driving, the trail drawn
    page.screenshot(path=out / "replay.png")
    page.close()
    os.unlink(f.name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "docs" / "screenshots"))
    parser.add_argument("--iterations", type=int, default=60)
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, served(str(Path(tmp) / "driftlab.db"), "--workers", "2") as url:
        job = tune(url, args.iterations)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            search_space(browser, url, job, out)
            chase_paused(browser, url, job, out)
            replay(browser, url, job, out)
            browser.close()
    print(f"screenshots of job {job['name']} ({job['n_done']} evaluations, best J {job['best']['J']:.4g}) in {out}")


if __name__ == "__main__":
    main()
