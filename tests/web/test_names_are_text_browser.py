"""Names a user typed reach every page as text: jobs and a study named with HTML and markdown that would run a
script, load a resource or format text, shown in the 3D view (the default job, the job dropdown, the compare
panel) and on the dashboard, in a real Chromium against a real server. No script runs, no request leaves for
what a name says, and each name reads as typed. Every page carries the security headers."""

import time

import httpx
import pytest

from tests.server_process import free_port, start_server, wait_status
from tests.web.chromium import choose_option, click_until_shown
from tests.web.test_view_browser import ConsoleLog

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

NAMES = [
    "<iframe srcdoc=\"<script>parent.fetch('/api/pwned-iframe')</script>\">",
    "<img src=/api/pwned-img onerror=\"fetch('/api/pwned-onerror')\">",
    "\"><svg onload=\"fetch('/api/pwned-svg')\">",
    "![chart](/api/pwned-markdown-image)",
    "a|b*c _d_ [e](/api/pwned-link) `f`",
]
STUDY_NAME = "<img src=/api/pwned-study onerror=\"fetch('/api/pwned-study-onerror')\">"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("names") / "driftlab.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    ids = []
    for n, name in enumerate(NAMES):  # iterations differ: the compare panel's config diff has a column per job
        job = httpx.post(f"{url}/api/jobs", json={"name": name, "iterations": n + 1, "robust_samples": 1,
                                                  "confirm_samples": 0, "seed_points": 1})
        assert job.status_code == 201, job.text
        ids.append(job.json()["id"])
    study = httpx.post(f"{url}/api/studies", json={"kind": "seeds", "name": STUDY_NAME, "seeds": [1],
                                                   "spec": {"iterations": 1, "robust_samples": 1,
                                                            "confirm_samples": 0}})
    assert study.status_code == 201, study.text
    for job_id in ids:
        wait_status(url, job_id, {"finished"}, timeout_s=600)
    yield url, ids
    proc.terminate()
    proc.wait(timeout=30)


def _watched(browser, url):
    """A page whose requests, dialogs and script errors are recorded."""
    page = browser.new_page(viewport={"width": 1400, "height": 1400})
    seen = {"requests": [], "dialogs": [], "errors": []}
    page.on("request", lambda r: seen["requests"].append(r.url))
    page.on("dialog", lambda d: (seen["dialogs"].append(d.message), d.dismiss()))
    page.on("pageerror", lambda e: seen["errors"].append(str(e)))
    log = ConsoleLog(page)
    page.goto(url)
    return page, log, seen


def _nothing_ran(seen):
    assert not [u for u in seen["requests"] if "pwned" in u], seen["requests"]
    assert not seen["dialogs"]


def test_the_view_shows_names_as_typed_and_runs_none_of_them(server, browser):
    url, ids = server
    page, log, seen = _watched(browser, f"{url}/viser/")
    log.wait_for("Connected!")
    page.get_by_role("combobox", name="Job").click()  # the dropdown lists every job by name
    for job_id, name in zip(ids, NAMES, strict=True):
        page.get_by_role("option", name=f"{job_id} · {name} · finished").wait_for()
    choose_option(page, "Job", f"{ids[0]} · {NAMES[0]} · finished")
    page.get_by_text(NAMES[0], exact=True).wait_for()  # the job line: **name**, read as typed
    click_until_shown(page.get_by_text("Compare", exact=True), page.get_by_role("button", name="Show comparison"))
    # "Job ids" (viser's text input has no label of its own)
    page.locator("input.mantine-TextInput-input").last.fill(",".join(str(i) for i in ids))
    show = page.get_by_role("button", name="Show comparison")
    click_until_shown(show, page.get_by_text(f"{NAMES[0]} (id {ids[0]})", exact=True).first)
    for job_id, name in zip(ids, NAMES, strict=True):
        page.get_by_text(f"{name} (id {job_id})", exact=True).first.wait_for()  # table and diff
    assert page.locator("iframe, svg[onload], img[onerror]").count() == 0
    page.wait_for_timeout(1000)  # a resource a name asked for would have been requested by now
    _nothing_ran(seen)
    page.close()


def test_the_study_dropdown_and_the_dashboard_show_names_as_text(server, browser):
    url, ids = server
    page, log, seen = _watched(browser, f"{url}/viser/")
    log.wait_for("Connected!")
    click_until_shown(page.get_by_text("Compare", exact=True), page.get_by_role("button", name="Show comparison"))
    choose_option(page, "Study", f"1 · {STUDY_NAME} · seeds", exact=False)
    show = page.get_by_role("button", name="Show comparison")
    click_until_shown(show, page.get_by_text(STUDY_NAME, exact=True).first)
    _nothing_ran(seen)
    page.close()
    page, _, seen = _watched(browser, f"{url}/dashboard/?job={ids[0]}")
    for name in NAMES:
        page.get_by_text(name, exact=False).first.wait_for()
    assert page.locator("iframe, svg[onload], img[onerror]").count() == 0
    _nothing_ran(seen)
    page.close()


@pytest.mark.parametrize("path", ["/", "/dashboard/", "/viser/", "/api/jobs", "/api/health", "/docs",
                                  "/api/nothing-here", "/dashboard/static/dashboard.js"])
def test_every_page_carries_the_security_headers(server, path):
    url, _ = server
    r = httpx.get(f"{url}{path}")
    assert r.headers["x-frame-options"] == "DENY" and r.headers["x-content-type-options"] == "nosniff"
    assert r.headers["referrer-policy"] == "no-referrer"
    assert "frame-ancestors 'none'" in r.headers["content-security-policy"]
    assert "object-src 'none'" in r.headers["content-security-policy"]


def test_a_page_of_another_origin_cannot_frame_the_dashboard(server, browser, tmp_path):
    url, _ = server
    other = tmp_path / "framer.html"
    other.write_text(f'<iframe id="f" src="{url}/dashboard/" width="800" height="600"></iframe>')
    page = browser.new_page()
    page.goto(other.as_uri())
    # The browser refuses to render the dashboard in the frame (X-Frame-Options, frame-ancestors): an error page.
    deadline = time.time() + 30
    while not (len(page.frames) > 1 and page.frames[1].url.startswith("chrome-error://")):
        assert time.time() < deadline, [f.url for f in page.frames]
        page.wait_for_timeout(100)
    assert page.frame_locator("#f").locator("button").count() == 0  # nothing of the dashboard to click
    page.close()
