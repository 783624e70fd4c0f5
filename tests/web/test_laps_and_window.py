"""The view on a several-lap run and the plant's drift window: the lap the car is on and each lap's mean |e| as
the downloads and the metrics cut them, and the window the drivability check decides, at each radius of the 8."""

import numpy as np
import pytest

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides
from driftlab.core.episode import COLUMNS, run_episode
from driftlab.core.track import FigureEight
from driftlab.reports.export import with_lap_column
from driftlab.services.read_model import drift_window_text
from driftlab.web.frames import EpisodeFrames
from driftlab.web.player import EpisodePlayer
from driftlab.web.viser_server import quiet_viser_server


@pytest.fixture(scope="module")
def three_laps():
    result = run_episode(Theta(), apply_overrides(EpisodeConfig(), {"scenario.laps": 3}), seed=1)
    assert result.status == "completed"
    return result


@pytest.fixture(scope="module")
def scene():
    server = quiet_viser_server(host="127.0.0.1", port=0)
    yield server.scene
    server.stop()


def test_the_view_cuts_laps_as_the_downloads_do(three_laps):
    track = FigureEight(laps=3)
    laps = EpisodeFrames(COLUMNS, three_laps.trajectory).laps_on(track)
    columns, rows = with_lap_column(list(COLUMNS), three_laps.trajectory, track)
    assert np.array_equal(laps, rows[:, columns.index("lap")])
    assert laps[0] == 1 and laps[-1] == 3 and np.all(np.diff(laps) >= 0)


def test_the_player_names_the_lap_and_each_laps_mean_error(three_laps, scene):
    player = EpisodePlayer(scene, FigureEight(laps=3))
    player.load(EpisodeFrames(COLUMNS, three_laps.trajectory))
    assert player.lap_text().startswith("lap **1 of 3**")
    player.seek(player.duration_s)
    text = player.lap_text()
    assert text.startswith("lap **3 of 3**")
    shown = [float(v) for v in text.split(": ")[1].removesuffix(" m").split(" · ")]
    assert shown == pytest.approx(three_laps.metrics.lap_mean_abs_e_m, abs=0.006)  # printed to 2 decimals
    player.set_track(FigureEight())
    assert player.lap_text() is None  # one lap: nothing to say


def test_the_drift_window_names_each_radius_and_whether_the_sideslip_is_inside():
    # The default plant drifts R 44 at 0.33-0.45 rad and R 25 at 0.25-0.56 (driftlab equilibrium --window).
    assert "R 44 m: 0.33-0.45 rad (0.4 inside)" in drift_window_text({"config": {}})
    text = drift_window_text({"config": {"scenario": {"left_radius_m": 25.0, "sideslip_rad": 0.5}}})
    assert "R 25 m: 0.25-0.56 rad (0.5 inside)" in text and "R 44 m: 0.33-0.45 rad (0.5 outside)" in text
