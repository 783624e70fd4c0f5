"""The chase camera in a real headless Chromium on the view's own viser server (in this process, on a real SQLite
file holding one real episode, reached through the API's relay as a user's browser reaches it): it follows the car
when paused and when the time is scrubbed, not only while the episode plays."""

import math
import threading
import time

import pytest
import uvicorn
from fastapi import FastAPI

from driftlab.core.config import Theta
from driftlab.core.tuning import TuningSpec
from driftlab.db import storage
from driftlab.server.view import RecordingCache, add_view_routes
from driftlab.web.scene import set_chase_camera
from driftlab.web.view_app import ViewApp
from driftlab.worker.executors import evaluate_episode
from tests.server_process import free_port
from tests.web.chromium import WAIT_S, click_until_shown

pytestmark = pytest.mark.e2e  # a browser


class _Camera:
    position = (0.0, 0.0, 0.0)
    look_at = (0.0, 0.0, 0.0)


def _expected_camera(frames, t_s):
    i = frames.index_at(t_s)
    x_m, y_m, _, _ = frames.pose_at(i)
    camera = _Camera()
    set_chase_camera(camera, x_m, y_m, frames.course_at(i))
    return camera.position


def _wait(condition, what, timeout_s=WAIT_S):
    deadline = time.time() + timeout_s
    while not condition():
        assert time.time() < deadline, what
        time.sleep(0.05)


def _scrub(page, slider, target_s, step_s=0.1):
    """Drag the time slider's thumb to about ``target_s``, then step to it exactly with the arrow keys (a press per
    0.1 s all the way would cost a rendered frame each)."""
    track = slider.locator("xpath=ancestor::*[contains(@class, 'mantine-Slider-root')]").bounding_box()
    thumb = slider.bounding_box()
    lo, hi = float(slider.get_attribute("aria-valuemin")), float(slider.get_attribute("aria-valuemax"))
    page.mouse.move(thumb["x"] + thumb["width"] / 2, thumb["y"] + thumb["height"] / 2)
    page.mouse.down()
    page.mouse.move(track["x"] + track["width"] * (target_s - lo) / (hi - lo), thumb["y"] + thumb["height"] / 2,
                    steps=5)
    page.mouse.up()
    slider.focus()
    for _ in range(50):
        off = round((target_s - float(slider.get_attribute("aria-valuenow"))) / step_s)
        if off == 0:
            return
        slider.press("ArrowRight" if off > 0 else "ArrowLeft")
    raise AssertionError(f"the time slider did not reach {target_s} s")


@pytest.fixture(scope="module")
def dashboard(tmp_path_factory):
    factory = storage.open_database(f"sqlite:///{tmp_path_factory.mktemp('chase') / 'driftlab.db'}")
    spec = TuningSpec(iterations=1, robust_samples=1, confirm_samples=0)
    outcome = evaluate_episode(Theta().as_dict(), spec.to_dict()["config"], 0)
    assert outcome.status == "completed" and outcome.trigger_points
    with storage.transaction(factory) as session:
        job = storage.create_job(session, name="chase", spec=spec.to_dict(), seed=0)
        storage.add_evaluation(session, job_id=job.id, theta=outcome.theta, J=outcome.J, status=outcome.status,
                               metrics=outcome.metrics, trigger_points=outcome.trigger_points,
                               wall_ms=outcome.wall_ms, columns=outcome.columns, trajectory=outcome.trajectory,
                               seeds=[{"seed": 0, "status": outcome.status, "J": outcome.J,
                                       "completed_fraction": 1.0}], trajectory_seed=0)
    view = ViewApp(factory, host="127.0.0.1", port=0)
    # The relay alone (no job runner): a browser's websocket cannot carry the relay's header itself (Chromium 150
    # sends no extra header on a websocket handshake), so the page is opened where users open it.
    app = FastAPI()
    add_view_routes(app, lambda: view.port, RecordingCache(factory), lambda: len(view.sessions))
    relay = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=free_port(), log_level="warning"))
    thread = threading.Thread(target=relay.run, daemon=True)
    thread.start()
    _wait(lambda: relay.started, "the relay's start")
    yield view, f"http://127.0.0.1:{relay.config.port}/viser/", outcome.trigger_points[0]["t_s"]
    relay.should_exit = True
    thread.join(timeout=10)
    view.stop()


def test_the_chase_camera_follows_the_car_when_paused_and_scrubbed(dashboard, browser):
    view, url, first_trigger_s = dashboard
    page = browser.new_page(viewport={"width": 900, "height": 600})
    page.goto(url)
    # The panel fills in under the buttons as the page lays out its data: a pointer click can wait for a button to
    # stand still longer than a loaded machine gives it (120 s once), so each is clicked until what it shows is there.
    click_until_shown(page.get_by_role("button", name="Play best"), page.get_by_role("button", name="Pause"))
    click_until_shown(page.get_by_role("button", name="Pause"), page.get_by_role("button", name="Play", exact=True))
    _wait(lambda: len(view.sessions) == 1, "the tab's session")
    session = next(iter(view.sessions.values()))
    frames = session.playback.player.frames

    page.get_by_text("Chase camera").click()  # switched on while paused: the camera goes to the car at once
    paused_at = session.playback.player.t_s
    expected = _expected_camera(frames, paused_at)
    _wait(lambda: math.dist(session.client.camera.position, expected) < 0.5,
          f"camera at {session.client.camera.position}, the car's chase position {expected}")

    target_s = round(first_trigger_s + 0.4, 1)  # mid-flick
    slider = page.get_by_role("slider").nth(1)  # playback speed, then time
    _scrub(page, slider, target_s)
    _wait(lambda: abs(session.playback.player.t_s - target_s) < 1e-6, f"scrubbed to {target_s} s")
    assert not session.playback.playing
    expected = _expected_camera(frames, target_s)
    _wait(lambda: math.dist(session.client.camera.position, expected) < 0.5,
          f"camera at {session.client.camera.position}, the car's chase position {expected} at {target_s} s")
    assert math.dist(expected, _expected_camera(frames, paused_at)) > 5.0  # the car moved, and the camera with it
    page.close()
