"""The episode runner's own controller as a policy of the environment: the MPC and the paper's steering feedback.

An environment episode driven by it is `driftlab episode`'s episode, bit for bit: the same trajectory, the same
status and J (docs/gym.md). It is a privileged policy: it reads what the runner's controller keeps between steps
(its disturbance estimate, its previous commands, the measured actuators) from the environment's loop, not from
the observation, and, as in the runner, a QP its solver cannot solve ends the episode ("solver_failed").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from driftlab.core.blas_threads import one_blas_thread
from driftlab.core.closed_loop import send_commands
from driftlab.core.episode import EpisodeRun
from driftlab.core.loop_state import I_DIRECTION, I_STATUS, SOLVER_FAILED
from driftlab.core.mpc import QpSession
from driftlab.core.track import LEFT, RIGHT
from driftlab.gym.env import FigureEightEnv, _compiled
from driftlab.gym.kernels import commands_after_qp, mpc_commands


class MpcPolicy:
    """``policy(observation) -> action``: the MPC's commands [delta rad, Fxr N] for the step the environment has
    just observed. A fresh solver per episode, as the runner has (no warm start survives an episode)."""

    def __init__(self, env: Any) -> None:
        unwrapped = env.unwrapped
        if not isinstance(unwrapped, FigureEightEnv):
            raise TypeError(f"an MPC policy drives DriftLab's environment, got {type(unwrapped).__name__}")
        self.env = unwrapped
        self._run: EpisodeRun | None = None
        self._out = np.zeros(2)
        self._kernel: Any = None  # resolved at the first episode: every episode passes the same types

    def _begin(self, run: EpisodeRun) -> None:
        model, s, loop, out = run.model, run.settings, run.loop, self._out
        self._run = run
        self._sessions = {LEFT: QpSession(model.left_qp), RIGHT: QpSession(model.right_qp)}
        qa_left, qa_right = model.left_qp.arrays, model.right_qp.arrays
        self._qa = {LEFT: qa_left, RIGHT: qa_right}
        args = (s, loop, qa_left, qa_right, model.params, out)
        if self._kernel is None:
            self._kernel = _compiled(mpc_commands, *args)
        commands = self._kernel
        self._commands = lambda: commands(*args)

    def __call__(self, observation: Any = None) -> np.ndarray:
        run = self.env.run
        if run is None:
            raise RuntimeError("reset the environment before asking the MPC for commands")
        if run is not self._run:
            self._begin(run)
        with one_blas_thread():  # the runner's bits whatever the process's BLAS threads (driftlab.core.blas_threads)
            if self._commands():
                return self._out.copy()
            loop = run.loop
            direction = int(loop.ints[I_DIRECTION])
            du, ok = self._sessions[direction].solve_constrained(loop.qp_q, loop.qp_lower, loop.qp_upper)
            commands_after_qp(run.settings, loop, self._qa[direction], du, self._out)
        if not ok:  # the runner sends these, then stops: the environment's next step ends the episode
            send_commands(loop, float(self._out[0]), float(self._out[1]))
            loop.ints[I_STATUS] = SOLVER_FAILED
        return self._out.copy()


def mpc_policy(env: Any) -> MpcPolicy:
    """The MPC of the environment's config (its ``controller``) as a policy: ``action = policy(observation)``."""
    return MpcPolicy(env)
