"""The dashboard page (/dashboard/) in a real headless Chromium against a real server process and SQLite file: jobs
started, paused, resumed, rescored and deleted from the page, through the REST API, with and without a token."""

import os
import re

import httpx
import pytest
from playwright.sync_api import expect

from tests.server_process import free_port, start_server, wait_released
from tests.web.chromium import click_until_shown
from tests.web.test_view_browser import SCREENSHOT_DIR

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("dashboard") / "driftlab.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    yield url
    proc.terminate()
    proc.wait(timeout=30)


def _page(browser, url):
    page = browser.new_page(viewport={"width": 1400, "height": 1400})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    return page, errors


def _wait_count(page, selector, attribute, more_than):
    """Until the plot at ``selector`` says (in ``attribute``) it drew more than ``more_than`` evaluations."""
    page.wait_for_function(
        "([sel, attr, n]) => Number(document.querySelector(sel)?.getAttribute(attr) || -1) > n",
        arg=[selector, attribute, more_than])
    return int(page.get_attribute(selector, attribute))


def _job_by_name(url, name):
    return next(j for j in httpx.get(f"{url}/api/jobs").json() if j["name"] == name)


def test_a_job_started_from_the_page_pauses_resumes_and_its_plots_follow(server, browser):
    page, errors = _page(browser, f"{server}/dashboard/")
    page.get_by_role("button", name="New job").click()
    form = page.locator("#job-form")
    form.locator("input[name=name]").fill("from-the-page")
    form.locator("input[name=iterations]").fill("400")  # long enough that it runs while paused and resumed
    form.locator("input[name=seed_points]").fill("6")
    form.locator("input[name=robust_samples]").fill("1")
    form.locator("input[name=confirm_samples]").fill("0")
    form.locator("select[name=plant_preset]").select_option("nominal")
    form.locator("textarea[name=sets]").fill("plant.steer_lag_s=0.02")
    form.locator("input[name=bound-k-hi]").fill("0.1")
    page.get_by_role("button", name="Start job").click()
    expect(page.locator("#job-title")).to_have_text("1 · from-the-page")

    job = _job_by_name(server, "from-the-page")
    spec = job["spec"]
    assert job["iterations"] == 400 and spec["robust_samples"] == 1 and spec["bounds"]["k"] == [0.0, 0.1]
    assert spec["config"]["plant"]["steer_lag_s"] == 0.02 and spec["config"]["plant"]["friction_circle"] is False

    # Live: the convergence plot and the search space (models refitted) grow as evaluations land.
    first = _wait_count(page, "#convergence", "data-n", 2)
    # The time left as a person says it ("about 7 min left"), not "about 6.913 min left".
    expect(page.locator("#job-status")).to_contain_text(re.compile(r"about (\d+ s|\d+ min|\d+\.\d h) left"))
    _wait_count(page, "#search-space", "data-n-evaluations", 2)
    _wait_count(page, "#slices", "data-n", first)
    assert page.locator("#contour-mean rect").count() > 900  # a 30 x 30 filled contour and its colour bar
    expect(page.locator("#importance-caption")).to_contain_text("ARD relevance")

    page.get_by_role("button", name="Pause").click()
    expect(page.locator("#job-status")).to_contain_text("status: paused")
    wait_released(server, job["id"])
    paused_at = httpx.get(f"{server}/api/jobs/{job['id']}").json()["n_done"]
    _wait_count(page, "#convergence", "data-n", paused_at - 1)  # the page has every stored evaluation
    # The best evaluation's drift and flicks in numbers, as stored (and as the report gives them).
    best = httpx.get(f"{server}/api/jobs/{job['id']}").json()["best"]
    phases = httpx.get(f"{server}/api/evaluations/{best['id']}").json()["metrics"]["phases"]
    rows = page.locator("#phase-table tbody tr")
    expect(rows).to_have_count(len(phases))
    first_flick = next(i for i, p in enumerate(phases) if p["phase"].startswith("inertia"))
    cells = rows.nth(first_flick).locator("td").all_text_contents()
    flick = phases[first_flick]
    assert cells[0] == "flick left → right" and cells[5] == f"{flick['flip_s']:.2f}"
    assert cells[2] == f"{flick['mean_abs_e_m']:.2f} / {flick['max_abs_e_m']:.2f}"
    assert cells[7] == f"{flick['speed_loss_mps']:.2f}"
    expect(page.locator("#phase-caption")).to_contain_text(f"evaluation id {best['id']}")
    expect(page.get_by_role("button", name="Resume")).to_be_enabled()

    page.get_by_role("button", name="Resume").click()
    expect(page.locator("#job-status")).to_contain_text("status: running")
    _wait_count(page, "#convergence", "data-n", paused_at)
    _wait_count(page, "#search-space", "data-n-evaluations", paused_at)

    click_until_shown(page.locator("#notes-box summary"), page.locator("#notes"))
    page.locator("#notes").fill("nominal plant, 20 ms lag")
    page.get_by_role("button", name="Save notes").click()
    expect(page.locator("#notes-saved")).to_have_text("saved")
    assert httpx.get(f"{server}/api/jobs/{job['id']}").json()["notes"] == "nominal plant, 20 ms lag"

    page.get_by_role("button", name="Pause").click()
    wait_released(server, job["id"])
    page.locator("#rescore-samples").fill("3")
    page.get_by_role("button", name="Rescore").click()
    expect(page.locator("#rescore-text")).to_contain_text(" / 3 completed")
    assert page.locator("#rescore-progress").get_attribute("max") == "3"
    assert not errors, errors
    page.close()


def test_delete_asks_first_and_cancel_keeps_the_job(server, browser):
    job = httpx.post(f"{server}/api/jobs", json={"name": "to-delete", "iterations": 3}).json()
    page, errors = _page(browser, f"{server}/dashboard/?job={job['id']}")
    expect(page.locator("#job-title")).to_have_text(f"{job['id']} · to-delete")
    page.get_by_role("button", name="Delete").click()
    expect(page.locator("#confirm-text")).to_contain_text(f"Delete job {job['id']} (to-delete)")
    page.get_by_role("button", name="Cancel").click()
    expect(page.locator("#confirm")).to_be_hidden()
    assert httpx.get(f"{server}/api/jobs/{job['id']}").status_code == 200

    if httpx.get(f"{server}/api/jobs/{job['id']}").json()["status"] in ("queued", "running"):
        page.get_by_role("button", name="Pause").click()  # a running job cannot be deleted (409): pause it first
        wait_released(server, job["id"])
    page.get_by_role("button", name="Delete").click()
    page.locator("#confirm-ok").click()
    expect(page.locator("#message")).to_contain_text(f"job {job['id']} (to-delete) deleted")
    assert httpx.get(f"{server}/api/jobs/{job['id']}").status_code == 404
    expect(page.locator(f"#job-table tr[data-job-id='{job['id']}']")).to_have_count(0)
    assert not errors, errors
    page.close()


AUTH = {"Authorization": "Bearer s3cret"}


def test_with_a_token_the_page_changes_nothing_without_it(tmp_path, browser):
    proc, url = start_server(tmp_path / "token.db", free_port(), env_extra={"DRIFTLAB_TOKEN": "s3cret"},
                             extra_args=("--workers", "1"))
    try:
        page, _ = _page(browser, f"{url}/dashboard/")
        # Without it the page reads nothing either: it says how to open it, and offers nothing to start.
        expect(page.locator("#message")).to_contain_text("401")
        expect(page.locator("#message")).to_contain_text("/dashboard/?token=")
        expect(page.get_by_role("button", name="New job")).to_be_disabled()
        assert httpx.get(f"{url}/api/jobs", headers=AUTH).json() == []
        assert httpx.get(f"{url}/api/jobs").status_code == 401  # reads need the token too
        page.close()
        page, _ = _page(browser, f"{url}/dashboard/?token=s3cret&job=1")
        # The token left the address (a 303 without it) for an HttpOnly cookie; no script can read a copy.
        assert page.url == f"{url}/dashboard/?job=1"
        assert page.evaluate("JSON.stringify(sessionStorage) + JSON.stringify(localStorage) + document.cookie") \
            == "{}{}"
        cookie = next(c for c in page.context.cookies() if c["name"] == "driftlab_token")
        assert cookie["httpOnly"] and cookie["sameSite"] == "Strict" and not cookie["secure"]  # http: not Secure
        page.get_by_role("button", name="New job").click()
        page.locator("#job-form input[name=iterations]").fill("2")
        page.get_by_role("button", name="Start job").click()
        expect(page.locator("#message")).to_contain_text("queued")
        assert len(httpx.get(f"{url}/api/jobs", headers=AUTH).json()) == 1
        page.close()
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_clone_with_changes_starts_from_the_jobs_settings(server, browser):
    original = httpx.post(f"{server}/api/jobs", json={
        "name": "original", "iterations": 2, "seed": 7, "robust_samples": 2, "bounds": {"k": [0.0, 0.08]},
        "config": {"plant.steer_lag_s": 0.05, "scenario.sideslip_rad": 0.42}}).json()
    page, errors = _page(browser, f"{server}/dashboard/?job={original['id']}")
    expect(page.locator("#job-title")).to_have_text(f"{original['id']} · original")
    page.get_by_role("button", name="Clone with changes").click()
    form = page.locator("#job-form")
    expect(form.locator("input[name=name]")).to_have_value("original-clone")
    assert form.locator("input[name=bound-k-hi]").input_value() == "0.08"
    sets = form.locator("textarea[name=sets]").input_value().splitlines()
    assert sorted(sets) == ["plant.steer_lag_s=0.05", "scenario.sideslip_rad=0.42"]
    form.locator("input[name=iterations]").fill("3")
    assert form.locator("input[name=warm_start_from]").input_value() == ""
    form.locator("input[name=warm_start_from]").fill(f" {original['id']} ")  # and warm-started from the original
    form.locator("input[name=time_budget_s]").fill("0.1")  # spent after its first evaluation
    page.get_by_role("button", name="Start job").click()
    expect(page.locator("#job-title")).to_contain_text("original-clone")
    clone = _job_by_name(server, "original-clone")
    changed = {k for k in original["spec"] if clone["spec"][k] != original["spec"][k]}
    assert changed == {"iterations"} and clone["iterations"] == 3  # the config in full, bounds, seed: as cloned
    # the same config: the original's evaluations are told to the clone's optimizer
    assert clone["spec"]["warm_start"]["from_jobs"] == [{"job_id": original["id"], "used_as": "told"}]
    assert clone["spec"]["stop"]["time_budget_s"] == 0.1
    expect(page.locator("#job-status")).to_contain_text("stopped by its rule: time budget")
    stopped = _job_by_name(server, "original-clone")
    assert stopped["status"] == "finished" and stopped["n_done"] < 3 and stopped["run_s"] >= 0.1
    assert not errors, errors
    page.close()


def test_a_car_calibrated_from_the_page_shows_its_progress_and_its_profile(server, browser):
    page, errors = _page(browser, f"{server}/dashboard/")
    click_until_shown(page.locator("#calibration-box summary"), page.locator("#calibration-form"))
    form = page.locator("#calibration-form")
    expect(form.locator("select[name=plant]")).to_have_value("commonroad_std")
    form.locator("textarea[name=sets]").fill("plant.model_drive_coupling=false")
    form.locator("input[name=points]").fill("0.5@44")
    form.locator("input[name=iterations]").fill("2")
    form.locator("input[name=seeds]").fill("1")
    page.get_by_role("button", name="Calibrate").click()
    expect(page.locator("#calibration-text")).to_contain_text("finished")
    calibration = httpx.get(f"{server}/api/calibrations").json()[-1]
    assert calibration["status"] == "finished" and calibration["request"]["points"] == "0.5@44"
    profile_id, = calibration["profile_ids"]
    row = page.locator("#profile-table tbody tr", has_text="commonroad_std 2").first
    expect(row).to_contain_text("0.5@44")
    assert row.locator("a").get_attribute("href") == f"/api/profiles/{profile_id}"
    assert not errors, errors
    page.close()


def test_a_clicked_point_selects_its_evaluation_plays_it_and_an_enqueued_theta_runs_next(server, browser):
    job = httpx.post(f"{server}/api/jobs", json={
        "name": "trials", "iterations": 300, "seed_points": 4, "robust_samples": 1, "confirm_samples": 0,
        "config": {"plant.steer_lag_s": 0.02}}).json()
    page, errors = _page(browser, f"{server}/dashboard/?job={job['id']}")
    expect(page.locator("#job-title")).to_have_text(f"{job['id']} · trials")
    _wait_count(page, "#convergence", "data-n", 5)

    # A point of the convergence plot -> its row in the table is selected -> "open in 3D view" plays it.
    point = page.locator("#convergence [data-eval-id]").nth(2)
    picked = int(point.get_attribute("data-eval-id"))
    assert f"evaluation id {picked}" in point.locator("title").text_content()  # what hovering shows
    point.click()
    expect(page.locator("#trials-table tr.picked")).to_have_attribute("data-eval-id", str(picked))
    expect(page.locator("#trial-picked")).to_contain_text(f"evaluation id {picked} ")
    link = page.locator("#trial-3d")
    assert link.get_attribute("href") == f"/api/evaluations/{picked}/replay.html"
    # What it plays names itself: the job, the evaluation, its J and theta, the plant, in the panel and the tab's
    # title (two such tabs are told apart), beside the state plots.
    evaluation = httpx.get(f"{server}/api/evaluations/{picked}").json()
    view = browser.new_page(viewport={"width": 1400, "height": 800})
    view.goto(f"{server}{link.get_attribute('href')}")
    panel = view.locator("#driftlab-panel")
    expect(panel.locator("h1")).to_have_text(f"job {job['id']} · trials · evaluation id {picked} "
                                             f"(index {evaluation['index']} in its job)")
    expect(panel).to_contain_text(f"J {evaluation['J']:.4g}")
    expect(panel).to_contain_text("plant: driftlab")
    for key, value in evaluation["theta"].items():
        expect(panel.locator("tr", has_text=key).first).to_contain_text(f"{value:.4g}")
    assert panel.locator("svg").count() >= 3  # the state plots
    assert f"evaluation id {picked}" in view.title() and f"job {job['id']}" in view.title()
    view.close()

    # Sorted by J: the completed evaluations first, lowest J on top.
    page.locator("#trials-table th", has_text="J").first.click()
    expect(page.locator("#trials-table th").nth(3)).to_have_text("J ▲")
    page.locator("#trials-status").select_option("completed")
    shown = [float(t) for t in page.locator("#trials-table tbody tr td:nth-child(4)").all_text_contents()]
    assert shown == sorted(shown) and len(shown) >= 1

    # Brushing the parallel coordinates' k axis (its upper 60%) filters the table to those k. The job is paused
    # first and the page has drawn its last evaluation: a redraw between measuring the axis and the drag moves it.
    httpx.post(f"{server}/api/jobs/{job['id']}/pause")
    wait_released(server, job["id"])
    stored = len(httpx.get(f"{server}/api/jobs/{job['id']}/evaluations").json())
    page.wait_for_function("n => Number(document.querySelector('#parallel')?.dataset.n) === n", arg=stored)
    page.locator("#trials-status").select_option("")
    page.locator("#parallel").scroll_into_view_if_needed()
    box = page.locator("#parallel .pc-hit[data-axis='k']").bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + 2)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + 0.6 * box["height"], steps=5)
    page.mouse.up()
    expect(page.locator("#trials-filter")).to_contain_text("brushed: k")
    # The lines outside the brush stand back (grey, under the others); a failed evaluation's line ends in the
    # "failed" band, dashed, not at the top of the J axis.
    lines = page.locator("#parallel path[data-in]")
    expect(lines).to_have_count(stored)
    inside = page.locator("#parallel path[data-in='1']").count()
    assert 0 < inside and inside + page.locator("#parallel path[data-in='0']").count() == stored
    assert all(p.get_attribute("stroke") == "#bbb" for p in page.locator("#parallel path[data-in='0']").all())
    failed = [e for e in httpx.get(f"{server}/api/jobs/{job['id']}/evaluations").json() if not e["completed"]]
    assert page.locator("#parallel path[data-failed='1']").count() == len(failed)
    if failed:
        expect(page.locator("#parallel text", has_text="failed")).to_have_count(1)
    if SCREENSHOT_DIR:  # the docs' picture of the brushed parallel coordinates
        page.locator("#parallel").screenshot(path=os.path.join(SCREENSHOT_DIR, "parallel_brushed.png"))
    k_column = [t.text_content() for t in page.locator("#trials-table th").all()].index("k") + 1
    ks = [float(t) for t in page.locator(f"#trials-table tbody tr td:nth-child({k_column})").all_text_contents()]
    low = 0.12 * 0.4 - 1e-3  # the job's box for k is [0, 0.12]; fmt rounds to 4 digits
    assert ks and all(k >= low for k in ks), ks
    page.locator("#trials-clear").click()
    expect(page.locator("#trials-filter")).to_have_text("")

    # "best 10": the ten lowest J of the completed evaluations, in the table and the parallel coordinates, kept in
    # the page's address (a reload or a shared link shows the same).
    evaluations = httpx.get(f"{server}/api/jobs/{job['id']}/evaluations").json()
    ten = {e["id"] for e in sorted((e for e in evaluations if e["completed"]), key=lambda e: e["J"])[:10]}
    page.locator("#trials-best").select_option("10")
    rows = page.locator("#trials-table tbody tr")
    expect(rows).to_have_count(len(ten))
    assert {int(r.get_attribute("data-eval-id")) for r in rows.all()} == ten
    expect(page.locator("#parallel path[data-in='1']")).to_have_count(len(ten))
    # ... and the convergence plot: the evaluations outside the filter grey (every one still drawn, and clickable)
    expect(page.locator("#convergence circle[data-eval-id]:not(.outside)")).to_have_count(len(ten))
    # The rank plot: each parameter against the rank of J, of the evaluations the table shows.
    expect(page.locator("#rank")).to_have_attribute("data-n", str(len(ten)))
    names = list(job["spec"]["bounds"])
    expect(page.locator("#rank svg")).to_have_count(len(names))
    expect(page.locator("#rank svg").first.locator("[data-eval-id]")).to_have_count(len(ten))
    if SCREENSHOT_DIR:  # the docs' pictures of the best-K filter and the rank plot
        page.locator("#trials-box").screenshot(path=os.path.join(SCREENSHOT_DIR, "trials_best_10.png"))
        page.locator("#rank").screenshot(path=os.path.join(SCREENSHOT_DIR, "rank_best_10.png"))
    assert "best=10" in page.url and f"job={job['id']}" in page.url
    again = browser.new_page(viewport={"width": 1400, "height": 1000})
    again.goto(page.url)
    expect(again.locator("#trials-best")).to_have_value("10")
    expect(again.locator("#trials-table tbody tr")).to_have_count(len(ten))
    again.close()
    page.locator("#trials-best").select_option("")

    # Enqueued from the page while the job is paused (nothing in flight): the next evaluation it runs, marked.
    done_before = httpx.get(f"{server}/api/jobs/{job['id']}").json()["n_done"]
    page.locator("#enqueue-form input[name=theta]").fill("k=0.061, dV=0.05")
    page.get_by_role("button", name="Enqueue").click()
    expect(page.locator("#enqueue-text")).to_contain_text("evaluated next")
    page.get_by_role("button", name="Resume").click()
    page.locator("#trials-status").select_option("enqueued")
    row = page.locator("#trials-table tbody tr")
    expect(row).to_have_count(1)
    expect(row.locator("td").nth(2)).to_contain_text("(enqueued)")
    if SCREENSHOT_DIR:  # the docs' picture of the table (DRIFTLAB_SCREENSHOTS=docs/screenshots)
        row.click()
        page.locator("#trials-box").screenshot(path=os.path.join(SCREENSHOT_DIR, "trials_enqueued.png"))
    marked = [e for e in httpx.get(f"{server}/api/jobs/{job['id']}/evaluations").json() if e["enqueued"]]
    assert len(marked) == 1 and marked[0]["theta"]["k"] == 0.061 and marked[0]["theta"]["dV"] == 0.05
    assert marked[0]["index"] == done_before
    httpx.post(f"{server}/api/jobs/{job['id']}/pause")
    wait_released(server, job["id"])
    assert not errors, errors
    page.close()
