"""What the view draws from: stored rows by time, sideslip colours, a job's convergence from a real SQLite file."""

import math

import numpy as np
import pytest

from driftlab.core.episode import COLUMNS
from driftlab.core.planner import Phase
from driftlab.core.track import LEFT, RIGHT
from driftlab.db import storage
from driftlab.web.frames import EpisodeFrames, sideslip_colors
from driftlab.web.sources import JobHistory, frames_of_evaluation


def _rows(n=5, dt=0.05):
    rows = np.zeros((n, len(COLUMNS)))
    rows[:, COLUMNS.index("t_s")] = np.arange(n) * dt
    rows[:, COLUMNS.index("x_m")] = np.arange(n)
    rows[:, COLUMNS.index("phase")] = [Phase.LEFT_DRIFT] * (n - 2) + [Phase.INERTIA_LEFT_TO_RIGHT] * 2
    rows[:, COLUMNS.index("psi_rad")] = 0.3
    rows[:, COLUMNS.index("beta_rad")] = -0.4
    return rows


def test_frame_lookup_takes_the_last_row_at_or_before_t():
    frames = EpisodeFrames(COLUMNS, _rows())
    assert frames.index_at(0.0) == 0
    assert frames.index_at(0.099) == 1  # between rows 1 (0.05 s) and 2 (0.10 s)
    assert frames.index_at(0.10) == 2
    assert frames.index_at(-1.0) == 0 and frames.index_at(99.0) == 4
    assert frames.duration_s == pytest.approx(0.2)
    assert frames.pose_at(3)[0] == 3.0
    assert frames.course_at(0) == pytest.approx(0.3 - 0.4)
    assert frames.tracked_circle_at(0) == LEFT and frames.tracked_circle_at(4) == RIGHT


def test_rows_must_match_the_columns():
    with pytest.raises(ValueError, match="rows must be"):
        EpisodeFrames(COLUMNS, np.zeros((3, 4)))


def test_sideslip_colours_blue_for_left_drift_red_for_right_grey_for_grip():
    left, grip, right, beyond = sideslip_colors(np.array([-0.4, 0.0, 0.4, 1.0]))
    assert left[2] > 200 and left[0] < 50  # blue
    assert right[0] > 200 and right[2] < 50  # red
    assert grip[0] == grip[1] == grip[2]  # grey
    assert (beyond == right).all()  # saturates


def test_job_history_reads_only_new_rows_and_tracks_the_best(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'view.db'}")
    rows = _rows()
    values = [(0.5, "completed"), (7.0, "spun_out"), (-0.2, "completed"), (0.1, "completed")]
    with storage.transaction(factory) as session:
        job = storage.create_job(session, name="j", spec={"iterations": 10}, seed=0)
        job_id = job.id
        for J, status in values[:2]:
            storage.add_evaluation(session, job_id=job_id, theta={"k": J}, J=J, status=status, metrics={},
                                   trigger_points=[], wall_ms=1.0, columns=list(COLUMNS), trajectory=rows)
    history = JobHistory(job_id)
    assert history.refresh(factory) and history.n_done == 2
    assert not history.refresh(factory)  # nothing new
    with storage.transaction(factory) as session:
        for J, status in values[2:]:
            storage.add_evaluation(session, job_id=job_id, theta={"k": J}, J=J, status=status, metrics={},
                                   trigger_points=[{"t_s": 0.1, "x_m": 1.0, "y_m": 2.0, "phase": 1}],
                                   wall_ms=1.0, columns=list(COLUMNS), trajectory=rows)
    assert history.refresh(factory) and history.n_done == 4
    index, j_done, best, failed = history.convergence()
    assert index.tolist() == [0, 1, 2, 3]
    assert math.isnan(j_done[1]) and j_done[2] == -0.2  # the failure's penalty is not a drift cost
    assert best.tolist() == [0.5, 0.5, -0.2, -0.2]
    assert failed[1] == 0.5 and np.isnan(failed[[0, 2, 3]]).all()  # marked at the top of completed J
    assert history.best_position() == 2
    frames = frames_of_evaluation(factory, history.ids[3])
    assert frames.index == 3 and frames.status == "completed" and frames.triggers_before(0.2)[0]["x_m"] == 1.0
    np.testing.assert_array_equal(frames.rows, rows)
