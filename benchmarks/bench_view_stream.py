"""CPU cost of streaming the 3D view: one car at 30 Hz to one browser tab.

Starts ``driftlab serve`` on a small finished job (the view replays its newest episode at 1x, forever),
then measures the server process's CPU time (user + system, from /proc) over windows of WINDOW_S seconds:
with no client and with one client through the API port's relay (viser's own port answers only the relay,
driftlab.web.viser_server). The client is a real headless
Chromium (a bare websocket client received one message and no scene: viser's page sends what it needs
first). Prints the median of
RUNS windows, in percent of one core.

    OMP_NUM_THREADS=1 python benchmarks/bench_view_stream.py
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.server_process import serve_finished_job  # noqa: E402
from tests.web.chromium import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

RUNS = 5
WINDOW_S = 10.0


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


def measure(pid: int) -> float:
    start_cpu, start = cpu_seconds(pid), time.monotonic()
    time.sleep(WINDOW_S)
    return 100.0 * (cpu_seconds(pid) - start_cpu) / (time.monotonic() - start)


def measure_with_browser(pid: int, browser, page_url: str) -> float:
    """CPU % of the server process while one browser tab shows the live view (the tab's own CPU not counted)."""
    page = browser.new_page(viewport={"width": 800, "height": 600})
    page.goto(page_url)
    page.get_by_text("Live (follows the job)").wait_for(timeout=60_000)
    page.wait_for_timeout(2000)  # scene received, first episode playing
    cpu = measure(pid)
    page.close()
    time.sleep(1.0)
    return cpu


def main() -> None:
    proc, url = serve_finished_job()
    try:
        idle = [measure(proc.pid) for _ in range(RUNS)]
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            relay = [measure_with_browser(proc.pid, browser, f"{url}/viser/") for _ in range(RUNS)]
            browser.close()
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    idle_cpu = statistics.median(idle)
    print(f"server process, no client:           {idle_cpu:5.2f} % of a core (median of {RUNS} x {WINDOW_S:.0f} s)")
    cpu = statistics.median(relay)
    print(f"server process, one tab via /viser:   {cpu:5.2f} % ({cpu - idle_cpu:+.2f} % for streaming; "
          f"runs {', '.join(f'{r:.2f}' for r in relay)})")


if __name__ == "__main__":
    main()
