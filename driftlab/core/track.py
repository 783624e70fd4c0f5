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

from driftlab.core.errors import ConfigError

TWO_PI = 2.0 * math.pi
LEFT = 1  # counter-clockwise circle, left-hand drift
RIGHT = -1  # clockwise circle, right-hand drift


def wrap_angle(angle_rad: float) -> float:
    """Wrap to (-pi, pi]."""
    wrapped = math.fmod(angle_rad + math.pi, TWO_PI)
    if wrapped <= 0.0:
        wrapped += TWO_PI
    return wrapped - math.pi


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
    """Two tangent circles of radii ``left_radius_m`` and ``right_radius_m`` meeting at P0 = (0, 0)."""

    left_radius_m: float = 44.0
    right_radius_m: float = 44.0

    def __post_init__(self) -> None:
        for name in ("left_radius_m", "right_radius_m"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 5.0 <= value <= 500.0):
                raise ConfigError(f"track.{name} must be a number in [5, 500], got {value!r}")

    @property
    def left(self) -> Circle:
        return Circle(0.0, self.left_radius_m, self.left_radius_m, LEFT)

    @property
    def right(self) -> Circle:
        return Circle(0.0, -self.right_radius_m, self.right_radius_m, RIGHT)

    def circle(self, direction: int) -> Circle:
        return self.left if direction == LEFT else self.right

    @property
    def scenario_length_m(self) -> float:
        """Half a left lap, a full right lap, half a left lap."""
        return TWO_PI * (self.left_radius_m + self.right_radius_m)

    def start_pose(self) -> tuple[float, float, float]:
        """(x, y, course) at the point of the left circle opposite P0, driving counter-clockwise."""
        return 0.0, 2.0 * self.left_radius_m, math.pi


def track_errors(circle: Circle, x_m: float, y_m: float, course_rad: float) -> TrackErrors:
    """Errors of a car at (x, y) with course angle psi + beta against ``circle`` (P0 at the origin)."""
    phi = circle.polar_angle(x_m, y_m)
    distance = math.hypot(x_m - circle.center_x_m, y_m - circle.center_y_m)
    lateral = circle.direction * (distance - circle.radius_m)
    course_error = wrap_angle(circle.heading_at(phi) - course_rad)
    p0_angle = circle.polar_angle(0.0, 0.0)
    swept = (p0_angle - phi) if circle.direction == LEFT else (phi - p0_angle)
    swept = swept % TWO_PI
    arc = swept * circle.radius_m
    return TrackErrors(lateral, course_error, arc, swept / TWO_PI)
