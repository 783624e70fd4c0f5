"""Figure-8 geometry on points whose answers are known by hand."""

import math

import numpy as np
import pytest

from driftlab.core.track import FigureEight, track_errors, wrap_angle

TRACK = FigureEight()
R = 44.0


def test_wrap_angle_range():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


def test_start_point_is_opposite_p0_half_a_lap_away():
    x, y, course = TRACK.start_pose()
    err = track_errors(TRACK.left, x, y, course)
    assert (x, y) == (0.0, 2 * R)
    assert err.lateral_error_m == pytest.approx(0.0, abs=1e-12)
    assert err.course_error_rad == pytest.approx(0.0, abs=1e-12)
    assert err.arc_to_p0_m == pytest.approx(math.pi * R)
    assert err.trigger_fraction == pytest.approx(0.5)


def test_quarter_lap_before_p0_on_each_circle():
    # Left circle, counter-clockwise: (-R, R) is a quarter lap before P0, heading -y.
    err = track_errors(TRACK.left, -R, R, -math.pi / 2)
    assert err.trigger_fraction == pytest.approx(0.25)
    assert err.course_error_rad == pytest.approx(0.0, abs=1e-12)
    err = track_errors(TRACK.left, R, R, math.pi / 2)
    assert err.trigger_fraction == pytest.approx(0.75)
    # Right circle, clockwise: (-R, -R) is a quarter lap before P0, heading +y.
    err = track_errors(TRACK.right, -R, -R, math.pi / 2)
    assert err.trigger_fraction == pytest.approx(0.25)
    assert err.course_error_rad == pytest.approx(0.0, abs=1e-12)


def test_just_before_and_after_p0():
    before = track_errors(TRACK.left, -1.0, 0.0114, 0.0)
    after = track_errors(TRACK.left, 1.0, 0.0114, 0.0)
    assert before.arc_to_p0_m == pytest.approx(1.0, rel=1e-3)
    assert after.trigger_fraction > 0.99


def test_lateral_error_positive_to_the_right_of_the_driving_direction():
    # Outside the left circle at its far point is to the right when driving counter-clockwise.
    assert track_errors(TRACK.left, 0.0, 2 * R + 1.5, math.pi).lateral_error_m == pytest.approx(1.5)
    assert track_errors(TRACK.left, 0.0, 2 * R - 1.5, math.pi).lateral_error_m == pytest.approx(-1.5)
    # Inside the right circle is to the right when driving clockwise.
    assert track_errors(TRACK.right, 0.0, -2 * R + 2.0, math.pi).lateral_error_m == pytest.approx(2.0)


def test_course_error_sign():
    # At P0 the path heads +x; a course rotated 0.1 rad to the right gives dpsi = +0.1.
    assert track_errors(TRACK.left, 0.0, 0.0, -0.1).course_error_rad == pytest.approx(0.1)


def test_unequal_radii():
    track = FigureEight(30.0, 60.0)
    assert track.right.center_y_m == -60.0
    assert track.scenario_length_m == pytest.approx(2 * math.pi * 90.0)
    assert track_errors(track.right, 0.0, -120.0, math.pi).trigger_fraction == pytest.approx(0.5)


def test_compiled_hypot_rounds_as_cpython_does():
    """The closed loop's lateral error uses track.hypot; stored episodes were computed with math.hypot, and one
    last bit is enough to move a knife-edge episode."""
    from driftlab.core.track import hypot

    rng = np.random.default_rng(0)
    xs, ys = (rng.standard_normal(20000) * 10 ** rng.uniform(-4, 3, 20000) for _ in range(2))
    assert all(hypot(x, y) == math.hypot(x, y) for x, y in zip(xs, ys, strict=True))
    assert hypot(0.0, 0.0) == 0.0 and math.isinf(hypot(math.inf, 1.0)) and math.isnan(hypot(math.nan, 1.0))
