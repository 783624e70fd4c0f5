"""The reference a step's sensing reuses from the step before is the one a fresh solve gives, never a stale one."""

import numpy as np

from driftlab.core.config import Theta
from driftlab.core.configure import preset_config
from driftlab.core.controller import drift_reference
from driftlab.core.episode import start_episode
from driftlab.core.loop_reference import step_reference
from driftlab.core.track import LEFT, RIGHT


def test_the_memo_hands_out_what_a_fresh_solve_gives_for_the_inputs_of_the_moment():
    run = start_episode(Theta(c_lr=0.0225, c_rl=0.0218, dV=-0.064, k=0.057), preset_config("default"), 0)
    cfg, st = run.settings, run.loop
    left, right = run.model.left_qp.arrays, run.model.right_qp.arrays
    estimates = [np.array([0.1, -0.02, 0.05]), np.array([0.1, -0.02, 0.05]), np.array([0.1, -0.02, 0.0]),
                 np.array([0.1, -0.02, -0.0]), np.array([0.1, -0.02, -0.0]), np.array([0.2, 0.0, 0.0]),
                 np.array([0.1, -0.02, 0.05])]
    for direction in (LEFT, RIGHT, LEFT):
        qa = left if direction == LEFT else right
        offset = cfg.speed_offset_left_mps if direction == LEFT else cfg.speed_offset_right_mps
        for estimate in estimates:
            st.estimate[:] = estimate  # control changes the estimate in place
            got = step_reference(cfg, st, left, right, direction)
            want = drift_reference(qa, st.estimate, direction, offset, True)
            assert got.tobytes() == want.tobytes()
            got[:] = 0.0  # the caller's copy: changing it leaves the memo as it was
            assert step_reference(cfg, st, left, right, direction).tobytes() == want.tobytes()
