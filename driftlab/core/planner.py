"""The inertia drift planner (paper section III-A): when to switch the reference drift.

The scenario on the figure 8: a left-hand drift from the point opposite P0 (half a lap), a flick into a
right-hand drift (one full lap), a flick back, half a left lap. The planner switches the reference
equilibrium *and* the reference circle when the trigger quantity of the circle being driven,
c = arc(P -> P0) / (2 pi R) (paper eq. 8), falls to the learned threshold: c_lr ends the left drift,
c_rl the right one. The inertia phase is the flick itself: from the trigger until the sideslip has reached
within ``settle_tolerance_rad`` of its new reference.

A trigger is armed only once the car is past the far half of its circle (c > 0.5 at some point, or the
start point), so a freshly switched circle, whose c starts near 0 behind P0, cannot fire at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

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


class InertiaDriftPlanner:
    """Tracks the phase; call :meth:`update` once per control step."""

    def __init__(self, triggers: Triggers, settle_tolerance_rad: float = 0.05) -> None:
        self.triggers = triggers
        self.settle_tolerance_rad = settle_tolerance_rad
        self.phase = Phase.LEFT_DRIFT
        self._armed = True  # the start point is the far point of the left circle
        self._final_far_half = False
        self._last_fraction = 0.5
        self.events: list[PlannerEvent] = []

    def update(self, time_s: float, x_m: float, y_m: float, trigger_fraction: float,
               sideslip_err_rad: float) -> Phase:
        """Advance the phase.

        Args:
            trigger_fraction: c of the circle of the current phase (from :func:`track_errors`).
            sideslip_err_rad: beta - beta_ref for the current reference.
        """
        # c falls to 0 at P0 and jumps to ~1 past it: a jump counts as reaching c = 0.
        crossed_p0 = self._last_fraction < 0.25 and trigger_fraction > 0.75
        self._last_fraction = trigger_fraction
        if trigger_fraction > 0.5 and not crossed_p0:
            self._armed = True
        phase = self.phase
        at_trigger = self._armed and (trigger_fraction <= self._threshold(phase) or crossed_p0)
        if phase == Phase.LEFT_DRIFT and at_trigger:
            self._switch(Phase.INERTIA_LEFT_TO_RIGHT, time_s, x_m, y_m)
        elif phase == Phase.RIGHT_DRIFT and at_trigger:
            self._switch(Phase.INERTIA_RIGHT_TO_LEFT, time_s, x_m, y_m)
        elif phase in (Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT):
            if abs(sideslip_err_rad) < self.settle_tolerance_rad:
                self.phase = Phase(phase + 1)
                self.events.append(PlannerEvent(time_s, self.phase, x_m, y_m))
        elif phase == Phase.LEFT_DRIFT_FINAL:
            # Done at the point opposite P0 again (c = 0.5), approached from c near 1.
            if 0.55 < trigger_fraction < 0.9:
                self._final_far_half = True
            if self._final_far_half and trigger_fraction <= 0.5:
                self.phase = Phase.FINISHED
                self.events.append(PlannerEvent(time_s, self.phase, x_m, y_m))
        return self.phase

    def _threshold(self, phase: Phase) -> float:
        return self.triggers.c_lr if phase == Phase.LEFT_DRIFT else self.triggers.c_rl

    def _switch(self, phase: Phase, time_s: float, x_m: float, y_m: float) -> None:
        self.phase = phase
        self._armed = False
        self.events.append(PlannerEvent(time_s, phase, x_m, y_m))

    @property
    def trigger_events(self) -> list[PlannerEvent]:
        return [e for e in self.events if e.phase in (Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT)]
