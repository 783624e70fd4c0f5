"""What-if latency: from a slider step in a real browser tab to the first frame of the new episode.

The view prints its own measurement (server side: slider update received -> episode run in the what-if
worker -> first frame queued) under the sliders; this reads it for N_STEPS steps of the k slider, with the
server idle and again while a tuning job keeps both job workers busy. Also prints the browser-side time
until the text appears (headless Chromium with software WebGL: slow to paint, an upper bound).

    OMP_NUM_THREADS=1 python benchmarks/bench_view_what_if.py
"""

from __future__ import annotations

import re
import statistics
import sys
import time
from pathlib import Path

import httpx
from playwright.sync_api import sync_playwright

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.server_process import serve_finished_job  # noqa: E402
from tests.web.chromium import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

N_STEPS = 9


def step_latencies(page) -> tuple[list[float], list[float]]:
    """(server-side ms, browser-side ms) for N_STEPS alternating steps of the k slider."""
    k_slider = page.get_by_role("slider").nth(5)
    server_ms, browser_ms = [], []
    for step in range(N_STEPS):
        before = page.get_by_text("after the slider").inner_text() if step else ""
        k_slider.focus()
        start = time.perf_counter()
        k_slider.press("ArrowRight" if step % 2 == 0 else "ArrowLeft")
        result = page.get_by_text("after the slider")
        deadline = time.time() + 30
        while time.time() < deadline:
            if result.count() and result.inner_text() != before and "running" not in result.inner_text():
                break
            page.wait_for_timeout(10)
        browser_ms.append(1000 * (time.perf_counter() - start))
        server_ms.append(float(re.search(r"first frame (\d+) ms", result.inner_text()).group(1)))
    return server_ms, browser_ms


def main() -> None:
    proc, url = serve_finished_job()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page(viewport={"width": 800, "height": 600})
            page.goto(f"{url}/viser/")
            page.get_by_text("Live (follows the job)").wait_for(timeout=60_000)
            page.get_by_text("What-if", exact=True).click()
            idle = step_latencies(page)
            httpx.post(f"{url}/api/jobs", json={"name": "busy", "iterations": 400})
            time.sleep(3.0)
            busy = step_latencies(page)
            browser.close()
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    for name, (server_ms, browser_ms) in (("idle server      ", idle), ("job running (2 w)", busy)):
        print(f"{name}: first frame {statistics.median(server_ms):4.0f} ms after the slider (median of {N_STEPS}, "
              f"max {max(server_ms):.0f}); text painted in the headless tab after "
              f"{statistics.median(browser_ms):.0f} ms")


if __name__ == "__main__":
    main()
