"""The inertia drift planner (paper section III-A): when to switch the reference drift.

The scenario on the figure 8: a left-hand drift from the point opposite P0 (half a lap), a flick into a
right-hand drift (one full lap), a flick back, half a left lap. The planner switches the reference
equilibrium *and* the reference circle when the trigger quantity of the circle being driven,
c = arc(P -> P0) / (2 pi R) (paper eq. 8), falls to the learned threshold: c_lr ends the left drift,
c_rl the right one. The inertia phase is the flick itself: from the trigger until the sideslip has reached
within ``settle_tolerance_rad`` of its new reference.

A trigger is armed only once the car is past the far half of its circle (c > 0.5 at some point, or the
start point), so a freshly switched circle, whose c starts near 0 behind P0, cannot fire at once.

Several laps (``scenario.laps``): the pattern repeats. Once the flick back into the left circle has settled, a
lap still to drive goes on as a left-hand drift for a full left lap (phase LEFT_DRIFT again, ending at c_lr),
so the run is half a left lap, then (right lap, left lap) x (laps - 1), a right lap and half a left lap.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from driftlab.core.track import LEFT, RIGHT


class Phase(IntEnum):
    """Phase of the scenario, in order."""

    LEFT_DRIFT = 0
    INERTIA_LEFT_TO_RIGHT = 1
    RIGHT_DRIFT = 2
    INERTIA_RIGHT_TO_LEFT = 3
    LEFT_DRIFT_FINAL = 4
    FINISHED = 5

    @property
    def direction(self) -> int:
        """The circle tracked: LEFT or RIGHT."""
        return RIGHT if self in (Phase.INERTIA_LEFT_TO_RIGHT, Phase.RIGHT_DRIFT) else LEFT

    @property
    def is_sustained(self) -> bool:
        return self in (Phase.LEFT_DRIFT, Phase.RIGHT_DRIFT, Phase.LEFT_DRIFT_FINAL)


@dataclass(frozen=True)
class Triggers:
    """Learned trigger thresholds: the fraction of a lap left before P0 at which to switch sides."""

    c_lr: float
    c_rl: float


@dataclass
class PlannerEvent:
    time_s: float
    phase: Phase
    x_m: float
    y_m: float


# The planner's state, as the compiled closed loop keeps it: [phase, armed, in the far half (final lap),
# last c, laps still to start after this one].
PLAN_PHASE, PLAN_ARMED, PLAN_FAR_HALF, PLAN_LAST_FRACTION, PLAN_LAPS_AFTER = range(5)
N_PLAN_STATE = 5


def initial_plan_state(laps: int = 1) -> np.ndarray:
    """The start: left-hand drift, armed (the start point is the far point of the left circle), ``laps`` laps
    of the 8 to drive."""
    return np.array([float(Phase.LEFT_DRIFT), 1.0, 0.0, 0.5, float(laps - 1)])


@njit(cache=True)
def phase_direction(phase):
    """The circle a phase tracks: LEFT or RIGHT (:attr:`Phase.direction`)."""
    return RIGHT if phase == 1 or phase == 2 else LEFT


@njit(cache=True)
def advance_phase(plan, trigger_fraction, sideslip_err_rad, c_lr, c_rl, settle_tolerance_rad):
    """One control step of the planner; updates ``plan`` in place and returns the phase (an int of
    :class:`Phase`) and whether it changed.

    Args:
        trigger_fraction: c of the circle of the current phase (from :func:`track_errors`).
        sideslip_err_rad: beta - beta_ref for the current reference.
    """
    # c falls to 0 at P0 and jumps to ~1 past it: a jump counts as reaching c = 0.
    crossed_p0 = plan[PLAN_LAST_FRACTION] < 0.25 and trigger_fraction > 0.75
    plan[PLAN_LAST_FRACTION] = trigger_fraction
    if trigger_fraction > 0.5 and not crossed_p0:
        plan[PLAN_ARMED] = 1.0
    phase = int(plan[PLAN_PHASE])
    threshold = c_lr if phase == 0 else c_rl
    at_trigger = plan[PLAN_ARMED] > 0.5 and (trigger_fraction <= threshold or crossed_p0)
    new_phase = phase
    if (phase == 0 or phase == 2) and at_trigger:
        new_phase = phase + 1
        plan[PLAN_ARMED] = 0.0
    elif phase == 1 or phase == 3:
        if abs(sideslip_err_rad) < settle_tolerance_rad:
            new_phase = phase + 1
            if phase == 3 and plan[PLAN_LAPS_AFTER] > 0.5:  # another lap: a full left lap to the trigger
                new_phase = 0
                plan[PLAN_LAPS_AFTER] -= 1.0
    elif phase == 4:
        # Done at the point opposite P0 again (c = 0.5), approached from c near 1.
        if 0.55 < trigger_fraction < 0.9:
            plan[PLAN_FAR_HALF] = 1.0
        if plan[PLAN_FAR_HALF] > 0.5 and trigger_fraction <= 0.5:
            new_phase = 5
    plan[PLAN_PHASE] = new_phase
    return new_phase, new_phase != phase


class InertiaDriftPlanner:
    """Tracks the phase; call :meth:`update` once per control step (the closed loop calls
    :func:`advance_phase` itself)."""

    def __init__(self, triggers: Triggers, settle_tolerance_rad: float = 0.05, laps: int = 1) -> None:
        self.triggers = triggers
        self.settle_tolerance_rad = settle_tolerance_rad
        self.state = initial_plan_state(laps)
        self.events: list[PlannerEvent] = []

    @property
    def phase(self) -> Phase:
        return Phase(int(self.state[PLAN_PHASE]))

    def update(self, time_s: float, x_m: float, y_m: float, trigger_fraction: float,
               sideslip_err_rad: float) -> Phase:
        """Advance the phase (see :func:`advance_phase`)."""
        phase, changed = advance_phase(self.state, trigger_fraction, sideslip_err_rad, self.triggers.c_lr,
                                       self.triggers.c_rl, self.settle_tolerance_rad)
        if changed:
            self.events.append(PlannerEvent(time_s, Phase(phase), x_m, y_m))
        return Phase(phase)

    @property
    def trigger_events(self) -> list[PlannerEvent]:
        return [e for e in self.events if e.phase in (Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT)]
