"""The environment's step, compiled: the closed loop's own halves (driftlab.core.closed_loop) with the commands a
policy chose, and the observation and stage cost written into one buffer, so that a step is one call from Python."""

from __future__ import annotations

from numba import njit

from driftlab.core.closed_loop import control, controller_commands, observe, send_commands, step_plant
from driftlab.core.loop_state import (
    C_BETA,
    C_BETA_REF,
    C_DPSI,
    C_E,
    C_PHASE,
    C_R_REF,
    C_V_REF,
    F_SEEN_C,
    F_SEEN_DPSI,
    F_SEEN_E,
    I_DIRECTION,
    I_ROWS,
)
from driftlab.core.metrics import stage_cost
from driftlab.core.plant import DRIVE, SIDESLIP, SPEED, STEER, YAW_RATE
from driftlab.core.track import LEFT
from driftlab.gym.spaces import (
    N_OBSERVATION,
    O_C,
    O_DPSI,
    O_DRIVE,
    O_E,
    O_PHASE,
    O_SIDESLIP,
    O_SIDESLIP_REF,
    O_SPEED,
    O_SPEED_REF,
    O_STEER,
    O_YAW_RATE,
    O_YAW_RATE_REF,
)

COST = N_OBSERVATION  # the buffer's last entry: the stage cost of the step observed
N_PHASES = 6


@njit(cache=True)
def _write_observation(st, out):
    """The observation of the step just observed (driftlab.gym.spaces) and its stage cost, from its row."""
    row = st.rows[st.ints[I_ROWS] - 1]
    sensed, floats = st.sensed, st.floats
    out[O_SPEED], out[O_SIDESLIP], out[O_YAW_RATE] = sensed[SPEED], sensed[SIDESLIP], sensed[YAW_RATE]
    out[O_E], out[O_DPSI], out[O_C] = floats[F_SEEN_E], floats[F_SEEN_DPSI], floats[F_SEEN_C]
    out[O_STEER], out[O_DRIVE] = st.plant[STEER], st.plant[DRIVE]
    out[O_SPEED_REF], out[O_SIDESLIP_REF], out[O_YAW_RATE_REF] = row[C_V_REF], row[C_BETA_REF], row[C_R_REF]
    for i in range(N_PHASES):
        out[O_PHASE + i] = 0.0
    out[O_PHASE + int(row[C_PHASE])] = 1.0
    # The row's own numbers, as J reads them (driftlab.core.metrics.objective_j): the sum of these is J's.
    out[COST] = stage_cost(row[C_E], row[C_DPSI], row[C_BETA] - row[C_BETA_REF])


@njit(cache=True)
def sense(cfg, st, qa_left, qa_right, noise, out):
    """:func:`~driftlab.core.closed_loop.observe`, then the observation written into ``out``; returns its status
    (RUNNING or how the episode ended)."""
    rows = st.ints[I_ROWS]
    status = observe(cfg, st, qa_left, qa_right, noise)
    if st.ints[I_ROWS] > rows:  # a row written (none when out of time)
        _write_observation(st, out)
    return status


@njit(cache=True)
def act(cfg, st, plant_params, actuator_params, steer_rad, drive_n):
    """Send the commands and step the plant (a plant stepped in Python: marked due, ``st.ints[I_PLANT_DUE]``)."""
    send_commands(st, steer_rad, drive_n)
    step_plant(cfg, st, plant_params, actuator_params)


@njit(cache=True)
def env_step(cfg, st, qa_left, qa_right, plant_params, actuator_params, noise, steer_rad, drive_n, out):
    """One control step of the closed loop with the given commands, for a plant stepped in the kernel: the plant's
    step, then the sensors, the planner, the row and the failure rules of the next; returns the status."""
    act(cfg, st, plant_params, actuator_params, steer_rad, drive_n)
    return sense(cfg, st, qa_left, qa_right, noise, out)


@njit(cache=True)
def mpc_commands(cfg, st, qa_left, qa_right, model_params, out):
    """The MPC's half of the step just observed: True with its commands [delta rad, Fxr N] in ``out[:2]``, or False
    where a limit is active (the QP's terms in ``st.qp_*``: solve it, then :func:`commands_after_qp`)."""
    du, within = control(cfg, st, qa_left, qa_right, model_params)
    if not within:
        return False
    qa = qa_left if st.ints[I_DIRECTION] == LEFT else qa_right
    out[0], out[1] = controller_commands(cfg, st, qa, du, False)
    return True


@njit(cache=True)
def commands_after_qp(cfg, st, qa, du, out):
    """The MPC's commands from the increments its QP solver returned."""
    out[0], out[1] = controller_commands(cfg, st, qa, du, True)
