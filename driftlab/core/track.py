"""The figure-8 track: two tangent circles meeting at P0 (paper section IV-A, Fig. 3).

Layout: P0 at the origin, both circles tangent to the x axis there and crossed heading +x. The left circle
(driven counter-clockwise, a left-hand drift) has its centre at (0, R_left); the right circle (clockwise)
at (0, -R_right). The radii may differ (the paper's future work).

Error conventions, chosen so that the paper's feedback delta_f = delta + k e_la with k > 0 steers the car
back (positive steer turns left):
- lateral error e > 0 when the car is to the right of the driving direction;
- course error dpsi = path heading - course (course = psi + beta), wrapped to (-pi, pi]: dpsi > 0 when the
  car's velocity points to the right of the path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from driftlab.core.errors import ConfigError

TWO_PI = 2.0 * math.pi
LEFT = 1  # counter-clockwise circle, left-hand drift
RIGHT = -1  # clockwise circle, right-hand drift
MAX_LAPS = 8


@njit(cache=True)
def wrap_angle(angle_rad: float) -> float:
    """Wrap to (-pi, pi]."""
    wrapped = np.fmod(angle_rad + math.pi, TWO_PI)
    if wrapped <= 0.0:
        wrapped += TWO_PI
    return wrapped - math.pi


@njit(cache=True)
def _exact_square(x: float) -> tuple[float, float]:
    """x * x as an unevaluated sum hi + lo (Dekker's product with Veltkamp's split)."""
    t = x * 134217729.0
    hi = t - (t - x)
    lo = x - hi
    p = hi * hi
    q = hi * lo + lo * hi
    z = p + q
    return z, p - z + q + lo * lo


@njit(cache=True)
def hypot(x: float, y: float) -> float:
    """sqrt(x^2 + y^2) exactly as CPython 3.11's ``math.hypot`` rounds it (its ``vector_norm``).

    numba's own hypot (C's) differs from it in the last bit now and then; stored episodes were computed with
    CPython's, and a bit is enough to move a knife-edge episode. ``tests/core/test_track.py`` checks the two agree.
    """
    x = abs(x)
    y = abs(y)
    largest = max(x, y)
    if math.isinf(largest):
        return largest
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if largest == 0.0:
        return largest
    exponent = math.frexp(largest)[1]
    scale = math.ldexp(1.0, -exponent)
    csum, frac1, frac2 = 1.0, 0.0, 0.0
    for v in (x * scale, y * scale):
        hi, lo = _exact_square(v)
        total = csum + hi
        frac2 += (csum - total) + hi
        csum = total
        frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi, lo = _exact_square(h)
    total = csum - hi
    frac2 += (csum - total) - hi
    csum = total
    frac1 -= lo
    h += (csum - 1.0 + (frac1 + frac2)) / (2.0 * h)
    return h / scale


@dataclass(frozen=True)
class Circle:
    """A driven circle: centre [m], radius [m] and direction (LEFT = counter-clockwise, RIGHT = clockwise)."""

    center_x_m: float
    center_y_m: float
    radius_m: float
    direction: int

    def polar_angle(self, x_m: float, y_m: float) -> float:
        return math.atan2(y_m - self.center_y_m, x_m - self.center_x_m)

    def closest_point(self, x_m: float, y_m: float) -> tuple[float, float]:
        """Closest point on the circle (the centre itself maps to the point at polar angle 0)."""
        phi = self.polar_angle(x_m, y_m)
        return (self.center_x_m + self.radius_m * math.cos(phi), self.center_y_m + self.radius_m * math.sin(phi))

    def point_at(self, phi_rad: float) -> tuple[float, float]:
        return (self.center_x_m + self.radius_m * math.cos(phi_rad),
                self.center_y_m + self.radius_m * math.sin(phi_rad))

    def heading_at(self, phi_rad: float) -> float:
        """Driving direction of the path tangent at polar angle phi."""
        return wrap_angle(phi_rad + self.direction * 0.5 * math.pi)


class TrackErrors(NamedTuple):
    """Where the car is relative to one circle."""

    lateral_error_m: float  # e, > 0 right of the driving direction
    course_error_rad: float  # dpsi = path heading - course, (-pi, pi]
    arc_to_p0_m: float  # along the driving direction, from the closest point to P0, [0, 2 pi R)
    trigger_fraction: float  # c = arc / (2 pi R), [0, 1)


@dataclass(frozen=True)
class FigureEight:
    """Two tangent circles of radii ``left_radius_m`` and ``right_radius_m`` meeting at P0 = (0, 0), driven
    ``laps`` times."""

    left_radius_m: float = 44.0
    right_radius_m: float = 44.0
    laps: int = 1

    def __post_init__(self) -> None:
        for name in ("left_radius_m", "right_radius_m"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 5.0 <= value <= 500.0):
                raise ConfigError(f"track.{name} must be a number in [5, 500], got {value!r}")
        if isinstance(self.laps, bool) or not isinstance(self.laps, int) or not 1 <= self.laps <= MAX_LAPS:
            raise ConfigError(f"track.laps must be an integer in [1, {MAX_LAPS}], got {self.laps!r}")

    @property
    def left(self) -> Circle:
        return Circle(0.0, self.left_radius_m, self.left_radius_m, LEFT)

    @property
    def right(self) -> Circle:
        return Circle(0.0, -self.right_radius_m, self.right_radius_m, RIGHT)

    def circle(self, direction: int) -> Circle:
        return self.left if direction == LEFT else self.right

    @classmethod
    def of_scenario(cls, scenario: dict) -> FigureEight:
        """The track of a stored scenario section (a config document's ``scenario``; absent keys: defaults)."""
        return cls(scenario.get("left_radius_m", 44.0), scenario.get("right_radius_m", 44.0), scenario.get("laps", 1))

    @property
    def lap_length_m(self) -> float:
        """One lap of the 8: half a left lap, a full right lap, half a left lap."""
        return TWO_PI * (self.left_radius_m + self.right_radius_m)

    @property
    def scenario_length_m(self) -> float:
        """Every lap (the pattern repeated ``laps`` times)."""
        return self.lap_length_m * self.laps

    def start_pose(self) -> tuple[float, float, float]:
        """(x, y, course) at the point of the left circle opposite P0, driving counter-clockwise."""
        return 0.0, 2.0 * self.left_radius_m, math.pi


def track_errors(circle: Circle, x_m: float, y_m: float, course_rad: float) -> TrackErrors:
    """Errors of a car at (x, y) with course angle psi + beta against ``circle`` (P0 at the origin)."""
    return TrackErrors(*circle_errors(circle.center_x_m, circle.center_y_m, circle.radius_m, circle.direction,
                                      x_m, y_m, course_rad))


@njit(cache=True)
def circle_errors(center_x_m, center_y_m, radius_m, direction, x_m, y_m, course_rad):
    """(e m, dpsi rad, arc to P0 m, c) of a car at (x, y) with course psi + beta against a circle (see
    :class:`TrackErrors`); the compiled closed loop calls this each control step."""
    phi = math.atan2(y_m - center_y_m, x_m - center_x_m)
    distance = hypot(x_m - center_x_m, y_m - center_y_m)
    lateral = direction * (distance - radius_m)
    course_error = wrap_angle(wrap_angle(phi + direction * 0.5 * math.pi) - course_rad)
    p0_angle = math.atan2(0.0 - center_y_m, 0.0 - center_x_m)
    swept = (p0_angle - phi) if direction == LEFT else (phi - p0_angle)
    swept = swept % TWO_PI
    return lateral, course_error, swept * radius_m, swept / TWO_PI


# The circles a calibration tiles besides the scenario's (driftlab.core.calibration.default_points), as a share of
# its radius: the paper's 44 m and circles of 30 m and 52 m.
TILED_RADIUS_SHARES = (30 / 44, 52 / 44)


def tiled_radii(radius_m: float) -> tuple[float, ...]:
    """The circle of ``radius_m`` and those a calibration tiles beside it, smallest first."""
    return tuple(sorted({float(radius_m), *(round(radius_m * share, 2) for share in TILED_RADIUS_SHARES)}))
