"""The reference a control step tracks: the drift equilibrium of the side driven, moved by the disturbance estimate
(offset-free MPC) and by dV (paper eq. 10), its speed moved toward the next circle's drift speed as a flick nears."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from driftlab.core.controller import drift_reference
from driftlab.core.planner import PLAN_LAST_FRACTION, PLAN_PHASE
from driftlab.core.track import LEFT, TWO_PI


@njit(cache=True)
def step_reference(cfg, st, qa_left, qa_right, direction):
    """z_ref of the side driven (:func:`drift_reference`), its speed moved toward the next circle's drift speed as
    the trigger nears.

    A step's sensing reads the reference the previous step's control computed: the same side, offset and estimate
    (the estimate changes only in control). It is kept in ``st.ref_memo`` under the bits of those inputs and handed
    out again rather than solved again (the offset-free target is a 3 x 3 LAPACK solve). The key's direction starts
    at 0, which no side has: the first call solves."""
    qa, qa_next = (qa_left, qa_right) if direction == LEFT else (qa_right, qa_left)
    offset = cfg.speed_offset_left_mps if direction == LEFT else cfg.speed_offset_right_mps
    if cfg.speed_change_accel_mps2 > 0.0:
        offset += _approach_offset_mps(cfg, st, direction, qa.z_eq[0], qa_next.z_eq[0])
    key, estimate = st.ref_memo_key, st.estimate
    if not (key[0] == direction and _same_bits(key[1], offset) and _same_bits(key[2], estimate[0])
            and _same_bits(key[3], estimate[1]) and _same_bits(key[4], estimate[2])):
        st.ref_memo[:] = drift_reference(qa, estimate, direction, offset, cfg.disturbance_gain > 0.0)
        key[0], key[1], key[2], key[3], key[4] = direction, offset, estimate[0], estimate[1], estimate[2]
    return st.ref_memo.copy()


@njit(cache=True)
def _same_bits(a, b):
    """a and b are the same float64 to the bit: equal, and of one sign where both are zero (a NaN never matches,
    which only costs a solve)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


@njit(cache=True)
def _approach_offset_mps(cfg, st, direction, speed_mps, next_speed_mps):
    """The planned speed change between circles of different drift speeds: in a sustained drift that ends in a
    flick, the reference speed follows V^2 = V_next^2 +- 2 a s, s the arc left to the trigger point, so that it
    reaches the next circle's drift speed at the trigger; the flick itself cannot shed (or gain) the difference
    (at 25/44 m 4.7 m/s: the car entered the small circle too fast and ran wide). 0 elsewhere."""
    phase = int(st.plan[PLAN_PHASE])
    if phase != 0 and phase != 2:
        return 0.0
    circle = cfg.left_circle if direction == LEFT else cfg.right_circle
    fraction = st.plan[PLAN_LAST_FRACTION]  # c of this circle at the last step
    trigger = cfg.c_lr if phase == 0 else cfg.c_rl
    if fraction > 0.75:  # just past P0 (c jumps to ~1 there): the circle has only begun
        return 0.0
    if fraction < trigger:  # at the trigger: the flick is due
        return next_speed_mps - speed_mps
    arc_m = (fraction - trigger) * TWO_PI * circle[2]
    accel = cfg.speed_change_accel_mps2 if next_speed_mps < speed_mps else -cfg.speed_change_accel_mps2
    planned_sq = next_speed_mps * next_speed_mps + 2.0 * accel * arc_m
    planned = np.sqrt(max(planned_sq, 0.0))
    low, high = min(speed_mps, next_speed_mps), max(speed_mps, next_speed_mps)
    return min(max(planned, low), high) - speed_mps
