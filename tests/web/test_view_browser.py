"""The 3D view in a real headless Chromium (Debian's package) against a real server and SQLite file."""

import io
import os
import re
import time

import httpx
import pytest
from matplotlib import image as mpimg

from tests.server_process import free_port, start_server, wait_released
from tests.web.chromium import WAIT_S, click_until_shown

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

SCREENSHOT_DIR = os.environ.get("DRIFTLAB_SCREENSHOTS")  # set to keep the screenshots


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("view") / "driftlab.db"
    # One worker: the runner runs one job at a time (with more, jobs run side by side, see tests/worker)
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    yield url
    proc.terminate()
    proc.wait(timeout=30)


class ConsoleLog:
    """Console lines of a page; Playwright delivers them only while it runs, hence page.wait_for_timeout."""

    def __init__(self, page):
        self.page = page
        self.lines: list[str] = []
        page.on("console", lambda message: self.lines.append(message.text))

    def wait_for(self, text, timeout_s=WAIT_S):
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            if any(text in line for line in self.lines):
                return next(line for line in self.lines if text in line)
            self.page.wait_for_timeout(100)
        raise AssertionError(f"console never printed {text!r}; it printed: {self.lines[-20:]}")


def _open(browser, url, height=1000):
    page = browser.new_page(viewport={"width": 1400, "height": height})
    log = ConsoleLog(page)
    page.goto(url)
    return page, log


def _screenshot_pixels(page, name):
    png = page.screenshot()
    if SCREENSHOT_DIR:
        os.makedirs(SCREENSHOT_DIR, exist_ok=True)
        with open(os.path.join(SCREENSHOT_DIR, name), "wb") as f:
            f.write(png)
    return mpimg.imread(io.BytesIO(png))[..., :3]


def _wait_for_evaluations(url, job_id, n, timeout_s=WAIT_S):
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        if httpx.get(f"{url}/api/jobs/{job_id}").json()["n_done"] >= n:
            return
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} has fewer than {n} evaluations after {timeout_s} s")


def _wait_for_clients(url, n, timeout_s=WAIT_S):
    deadline = time.time() + timeout_s
    while (clients := httpx.get(f"{url}/api/view").json()["clients"]) != n:
        assert time.time() < deadline, f"{clients} view clients, not {n}, after {timeout_s} s"
        time.sleep(0.1)


def _wait_until_played(page, t_s):
    """Until the HUD's clock reads at least ``t_s`` (it is written 5 times a second while playing)."""
    page.wait_for_function(
        r"""t => { const m = /· t\s+([\d.]+) \//.exec(document.body.innerText); return m && Number(m[1]) >= t; }""",
        arg=t_s, polling=250)


@pytest.fixture(scope="module")
def job(server):
    r = httpx.post(f"{server}/api/jobs", json={"name": "view", "iterations": 16, "seed_points": 8})
    assert r.status_code == 201, r.text
    return r.json()


def test_live_view_connects_and_shows_evaluations(server, browser, job):
    page, log = _open(browser, f"{server}/viser/")
    connected = log.wait_for("Connected!")
    assert connected.endswith("/viser")  # the websocket went through the API's port, not viser's own
    _wait_for_evaluations(server, job["id"], 3)
    page.get_by_text("Live (follows the job)").wait_for()
    status = page.get_by_text(re.compile(r"^view: (queued|running|finished), \d+ / 16 evaluations")).first
    status.wait_for()
    _wait_until_played(page, 2.0)  # a couple of seconds of driving: trail and car on screen
    pixels = _screenshot_pixels(page, "live.png")
    scene = pixels[:, : int(pixels.shape[1] * 0.6)]  # the 3D canvas, left of the control panel
    assert scene.std() > 0.05, "the 3D view looks blank"
    # The trail is drawn in saturated blue or red (sideslip colours); grey ground and track are not.
    saturation = scene.max(axis=-1) - scene.min(axis=-1)
    assert (saturation > 0.4).mean() > 1e-4, "no sideslip-coloured trail in the view"
    page.close()


def test_two_tabs_at_once_each_get_their_own_view(server, browser, job):
    pages = [_open(browser, f"{server}/viser/") for _ in range(2)]
    for page, log in pages:
        log.wait_for("Connected!")
        page.get_by_text("Live (follows the job)").wait_for()
    # The tabs of the earlier tests are closed, but their websockets close through the relay a moment later.
    _wait_for_clients(server, 2)
    # Pausing one tab leaves the other playing.
    pages[0][0].get_by_role("button", name="Pause").click()
    pages[0][0].get_by_role("button", name="Play", exact=True).wait_for()
    assert pages[1][0].get_by_role("button", name="Pause").is_visible()
    for page, _ in pages:
        page.close()


def test_what_if_slider_replays_a_new_episode(server, browser, job):
    _wait_for_evaluations(server, job["id"], 16)
    page, log = _open(browser, f"{server}/viser/")
    log.wait_for("Connected!")
    page.get_by_text("Live (follows the job)").wait_for()
    click_until_shown(page.get_by_text("What-if", exact=True),
                      page.get_by_role("button", name="Reset to the best theta and the job's plant"))
    k_slider = page.get_by_role("slider").nth(5)  # playback speed, time, then c_lr, c_rl, dV, k
    assert k_slider.get_attribute("aria-valuemax") == "0.12"
    k_slider.focus()
    k_slider.press("ArrowRight")
    result = page.get_by_text("after the slider")
    result.wait_for()
    text = result.inner_text()
    latency_ms = float(re.search(r"first frame (\d+) ms", text).group(1))
    # How long is measured by benchmarks/bench_view_what_if.py; here only that it was measured (on a loaded
    # 2-core machine the episode can take seconds).
    assert latency_ms > 0, text
    page.get_by_text("What-if", exact=False).first.wait_for()
    _screenshot_pixels(page, "what_if.png")
    page.close()


def test_what_if_with_no_slider_moved_scores_what_the_ghost_scores(server, browser, job):
    # The what-if episode runs on the ghost's seed: the best theta itself, unmoved, is the ghost's episode.
    _wait_for_evaluations(server, job["id"], 16)
    best = httpx.get(f"{server}/api/jobs/{job['id']}/best").json()
    page, log = _open(browser, f"{server}/viser/")
    log.wait_for("Connected!")
    page.get_by_text("Live (follows the job)").wait_for()
    reset = page.get_by_role("button", name="Reset to the best theta and the job's plant")
    click_until_shown(page.get_by_text("What-if", exact=True), reset)
    result = page.get_by_text("after the slider")
    click_until_shown(reset, result)  # a click the panel's redraw swallowed under load is clicked again
    text = result.inner_text()
    found = re.search(r"what-if: (\w+), J (\S+) \(one episode, seed (\d+)\); ghost \(evaluation id (\d+), same seed\): "
                      r"J (\S+) \(its mean over (\d+) seeds: (\S+)\); plant: the job's", text)
    assert found, text
    status, j_what_if, seed, ghost_id, j_ghost, n_seeds, j_mean = found.groups()
    assert status == "completed" and j_what_if == j_ghost
    assert int(ghost_id) == best["id"] and int(seed) == best["trajectory_seed"]
    worst = [s for s in best["seeds"] if s["seed"] == int(seed)][0]
    assert float(j_ghost) == float(f"{worst['J']:.4g}") and float(j_mean) == float(f"{best['J']:.4g}")
    assert int(n_seeds) == len(best["seeds"])
    # "add to job": the sliders' theta enqueued for the job, evaluated next (a finished job first says why not)
    add = page.get_by_role("button", name="Add this theta to the job (evaluated next)")
    add.click()
    page.get_by_text(re.compile(r"not added: job \d+ is finished; raise its budget first")).wait_for()
    # a larger budget, paused (nothing in flight), then added and resumed: the next evaluation is the sliders' theta
    assert httpx.patch(f"{server}/api/jobs/{job['id']}", json={"iterations": 100}).status_code == 200
    httpx.post(f"{server}/api/jobs/{job['id']}/pause")
    wait_released(server, job["id"])
    done = httpx.get(f"{server}/api/jobs/{job['id']}").json()["n_done"]
    add.click()
    page.get_by_text(re.compile(r"added to job \d+ \(queue entry \d+\): it is evaluated next")).wait_for()
    assert httpx.post(f"{server}/api/jobs/{job['id']}/resume").status_code == 200
    deadline = time.time() + WAIT_S
    while not (marked := [e for e in httpx.get(f"{server}/api/jobs/{job['id']}/evaluations").json() if e["enqueued"]]):
        assert time.time() < deadline, "the enqueued theta was never evaluated"
        time.sleep(0.5)
    httpx.post(f"{server}/api/jobs/{job['id']}/pause")
    wait_released(server, job["id"])
    # asked first after the resume; stored in order of completion, and the one asked beside it may finish first
    assert marked[0]["index"] in (done, done + 1) and marked[0]["theta"] == best["theta"]
    page.close()


def test_recording_plays_back_from_storage(server, browser, job):
    best = httpx.get(f"{server}/api/jobs/{job['id']}/best").json()
    recording = httpx.get(f"{server}/api/evaluations/{best['id']}/recording.viser")
    assert recording.status_code == 200 and len(recording.content) > 10_000
    html = httpx.get(f"{server}/api/evaluations/{best['id']}/replay.html")
    assert html.status_code == 200 and "__VISER_EMBED_DATA__" in html.text
    assert f"<h1>job {job['id']} · {job['name']} · evaluation id {best['id']} " in html.text  # the job, the plant
    assert "<p>plant: driftlab</p>" in html.text and f"<title>job {job['id']}" in html.text
    page, log = _open(browser, f"{server}/viser/?playbackPath=/api/evaluations/{best['id']}/recording.viser")
    log.wait_for("File loaded!")
    deadline = time.time() + WAIT_S  # the player fades the scene in over the first seconds (longer under load)
    while _screenshot_pixels(page, "rewatch_recording.png").std() <= 0.05:
        assert time.time() < deadline, "the recording's view looks blank"
        page.wait_for_timeout(500)
    page.close()


def test_landing_page_links_the_view(server):
    page = httpx.get(f"{server}/").text
    assert 'href="/viser/"' in page and 'href="/docs"' in page and 'href="/dashboard/"' in page
    assert f"curl -X POST {server}/api/jobs" in page  # the address it is served at, not localhost:8000


def test_an_empty_job_shows_nothing_of_another_job(server, browser, job):
    _wait_for_evaluations(server, job["id"], 16)
    # With one worker the runner takes one job at a time, in order: behind a long job, a new one stays empty.
    busy = httpx.post(f"{server}/api/jobs", json={"name": "busy", "iterations": 5000, "seed_points": 5}).json()
    _wait_for_evaluations(server, busy["id"], 1)
    empty = httpx.post(f"{server}/api/jobs", json={"name": "empty", "iterations": 10}).json()
    try:
        page, log = _open(browser, f"{server}/viser/")
        log.wait_for("Connected!")
        page.get_by_text("Waiting for the first evaluation of job empty").wait_for()
        assert not page.get_by_text("Live (follows the job)").is_visible()
        assert not page.get_by_text(re.compile("newest: ")).is_visible()
        page.close()
        assert httpx.delete(f"{server}/api/jobs/{empty['id']}").status_code == 204  # queued, not running
        page, log = _open(browser, f"{server}/viser/")  # now the newest is busy, playing live
        log.wait_for("Connected!")
        page.get_by_text(re.compile(r"newest: evaluation id \d+ \(index \d+\)")).wait_for()
        page.get_by_text(re.compile(r"evaluation id \d+ \(index \d+ in its job\)")).first.wait_for()
        page.close()
    finally:
        for j in (busy, empty):
            httpx.post(f"{server}/api/jobs/{j['id']}/pause")
        deadline = time.time() + 60
        while httpx.get(f"{server}/api/jobs/{busy['id']}").json()["runner_id"] and time.time() < deadline:
            time.sleep(0.2)
        for j in (busy, empty):
            assert httpx.delete(f"{server}/api/jobs/{j['id']}").status_code in (204, 404)
