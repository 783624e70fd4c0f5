"""The compare mode and the robustness heatmap in a real headless Chromium against a real server process
(one job worker) and SQLite file; screenshots go to a temporary folder (and to DRIFTLAB_SCREENSHOTS if set)."""

import io
import os

import httpx
import numpy as np
import pytest
from matplotlib import image as mpimg

from tests.server_process import free_port, start_server
from tests.web.chromium import choose_option, click_until_shown
from tests.web.test_view_browser import SCREENSHOT_DIR, ConsoleLog, _wait_until_played

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

JOB_SPEC = {"iterations": 6, "seed_points": 6, "robust_samples": 1, "confirm_samples": 0}
GRID = {"plant.friction_scale": [0.9, 1.0, 1.1, 1.2], "plant.mass_scale": [0.9, 1.0, 1.1]}


def _wait_study(url, study_id, timeout_s=180):
    import time

    deadline = time.time() + timeout_s
    while time.time() < deadline:
        study = httpx.get(f"{url}/api/studies/{study_id}").json()
        if study["status"] == "finished":
            return study
        time.sleep(0.3)
    raise AssertionError(f"study {study_id} did not finish: {study['status']}")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("compare") / "driftlab.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    seeds = httpx.post(f"{url}/api/studies", json={"kind": "seeds", "name": "three", "seeds": [0, 1, 2],
                                                   "spec": JOB_SPEC}).json()
    grid = httpx.post(f"{url}/api/studies", json={"kind": "robustness", "name": "grip", "theta": {"k": 0.05},
                                                  "grid": GRID}).json()
    yield url, _wait_study(url, seeds["id"]), _wait_study(url, grid["id"])
    proc.terminate()
    proc.wait(timeout=30)


def _save(png, name, tmp_path):
    for folder in filter(None, (str(tmp_path), SCREENSHOT_DIR)):
        os.makedirs(folder, exist_ok=True)
        with open(os.path.join(folder, name), "wb") as f:
            f.write(png)
    return mpimg.imread(io.BytesIO(png))[..., :3]


def _open_compare(browser, url, study_label, shown):
    """The view's Compare panel showing the study ``study_label``, once the text ``shown`` is drawn."""
    page = browser.new_page(viewport={"width": 1400, "height": 1300})
    log = ConsoleLog(page)
    page.goto(f"{url}/viser/")
    log.wait_for("Connected!")
    click_until_shown(page.get_by_text("Compare", exact=True), page.get_by_role("button", name="Show comparison"))
    choose_option(page, "Study", study_label)
    click_until_shown(page.get_by_role("button", name="Show comparison"), page.get_by_text(shown).first)
    return page


def test_compare_mode_overlays_a_seeds_study_and_plays_its_best_episodes_together(server, browser, tmp_path):
    url, seeds, _ = server
    page = _open_compare(browser, url, f"{seeds['id']} · three · seeds · finished",
                         "three (seeds, finished); final best J from")
    summary = page.get_by_text("three (seeds, finished); final best J from")
    final = seeds["final_best_J"]
    assert f"from {min(final):.4g} to {max(final):.4g}, median {np.median(final):.4g}" in summary.inner_text()
    for job_id in seeds["job_ids"]:  # one row per job, its best J as the API has it
        job = httpx.get(f"{url}/api/jobs/{job_id}").json()
        page.get_by_text(f"{job['name']} (id {job_id})").first.wait_for()
    # Each job's best episode through its flicks, as stored (metrics.phases).
    first = httpx.get(f"{url}/api/compare", params={"jobs": str(seeds["job_ids"][0])}).json()[0]
    flick = next(p for p in first["best_phases"] if "flip_s" in p)
    # the whole cell: the speed loss as the dashboard shows it, and the mean |e| (a bare | once cut it off)
    page.get_by_text(f"{flick['flip_s']:.2f} / {flick['settle_s']:.2f} s, loses {flick['speed_loss_mps']:.2f} m/s, "
                     f"mean |e| {flick['mean_abs_e_m']:.2f} m", exact=False).first.wait_for()
    plot = page.locator(".uplot", has=page.get_by_text("Compare: best J so far (completed)"))
    plot.wait_for()
    # The config diff: a seeds study's jobs differ in their seed only.
    diff = page.locator("table", has=page.get_by_text("setting", exact=True))
    diff.wait_for()
    assert [td.inner_text() for td in diff.locator("tbody tr").first.locator("td").all()] == ["seed", "0", "1", "2"]
    assert diff.locator("tbody tr").count() == 1
    page.get_by_role("button", name="Play best episodes together").click()
    page.get_by_text("Compare (best episodes together)").wait_for()
    for n, name in enumerate(("red car", "blue ghost", "green ghost")):
        page.get_by_text(f"{name}: three-seed{n}").wait_for()
    _wait_until_played(page, 2.0)  # the cars drive for a moment
    pixels = _save(page.screenshot(), "compare.png", tmp_path)
    scene = pixels[:, : int(pixels.shape[1] * 0.6)]
    assert scene.std() > 0.05, "the 3D view looks blank"
    plot_pixels = mpimg.imread(io.BytesIO(plot.screenshot()))[..., :3]
    assert plot_pixels.std() > 0.05, "the comparison plot looks blank"
    # The shaded 25-75 % band: light blue pixels (blue above red and green).
    bluish = (plot_pixels[..., 2] > plot_pixels[..., 0] + 0.05) & (plot_pixels[..., 2] > 0.8)
    assert bluish.mean() > 0.005, "no shaded band in the comparison plot"
    page.close()


def test_the_heatmap_shows_each_cell_as_stored(server, browser, tmp_path):
    url, _, grid = server
    page = _open_compare(browser, url, f"{grid['id']} · grip · robustness · finished",
                         "grip (robustness, finished): 12 of 12 cells run")
    table = page.locator("table", has=page.get_by_text("plant.friction_scale"))
    table.wait_for()
    rows = table.locator("tr").all()[2:]  # below the column key's row and the column values' row
    shown = [[td.inner_text() for td in row.locator("td").all()] for row in rows]
    expected = [c["J"] if c["status"] == "completed" else c["status"] for c in grid["cells"]]
    expected = [f"{v:.4g}" if isinstance(v, float) else v for v in expected]
    assert [text for row in shown for text in row] == expected
    assert [row.locator("th").inner_text() for row in rows] == [str(v) for v in GRID["plant.friction_scale"]]
    pixels = _save(page.screenshot(), "heatmap.png", tmp_path)
    table_pixels = mpimg.imread(io.BytesIO(table.screenshot()))[..., :3]
    assert table_pixels.std() > 0.05 and pixels.std() > 0.05, "the heatmap looks blank"
    page.close()
