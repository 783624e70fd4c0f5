"""The episode kernel with CommonRoad's MB stepped in compiled code.

A module of its own, compiled only where an MB episode runs: the shared kernel
(:func:`driftlab.core.closed_loop.run_until_constrained`) leaves a plant it does not step (``PLANT_EXTERNAL``) to
its caller after each control step, so that its first compile does not carry MB's derivatives (~8 s). This caller
is compiled: it steps MB and goes on, and returns to Python only for a constrained QP or the end.
"""

from __future__ import annotations

from numba import njit

from driftlab.core.closed_loop import I_PLANT_DUE, NEEDS_PLANT, run_until_constrained
from driftlab.core.commonroad.plant import mb_recorded_step


@njit(cache=True, error_model="numpy")
def run_mb_until_constrained(cfg, st, qa_left, qa_right, model_params, p, act, noise, lowest_load_n, record):
    """:func:`run_until_constrained` (DONE or NEEDS_QP), MB stepped as
    :meth:`~driftlab.core.commonroad.plant.CommonRoadMbPlant.step` steps it whenever the kernel asks."""
    while True:
        code = run_until_constrained(cfg, st, qa_left, qa_right, model_params, p, act, noise)
        if code != NEEDS_PLANT:
            return code
        st.plant[:] = mb_recorded_step(st.plant, st.last_applied[0], st.last_applied[1], cfg.dt_s, cfg.substep_s,
                                       p, act, lowest_load_n, record)
        st.ints[I_PLANT_DUE] = 0
