"""One episode's use of a condensed QP: the solver instance (OSQP or DAQP), set up on first need."""

from __future__ import annotations

import daqp
import numpy as np

from driftlab.core.mpc.arrays import MpcSolution
from driftlab.core.mpc.condensing import ReferenceQp
from driftlab.core.mpc.kernels import constrained_terms, next_commands, reference_terms, unconstrained_increments
from driftlab.core.mpc_config import KN, N_U


class QpSession:
    """One episode's use of a :class:`ReferenceQp`: the OSQP instance, set up on first need.

    Kept apart from the cached :class:`ReferenceQp` so that no solver state (OSQP's warm start, its adapted
    rho) survives from one episode to the next: an episode is a pure function of its inputs.
    """

    def __init__(self, qp: ReferenceQp) -> None:
        self.qp = qp
        self._solver = None

    def _osqp(self):
        if self._solver is None:
            import osqp  # only the osqp solver needs it (~0.2 s of a cold start)
            import scipy.sparse as sp

            qp = self.qp
            solver = osqp.OSQP()
            solver.setup(
                sp.csc_matrix(np.triu(qp.hessian)), np.zeros(qp.hessian.shape[0]),
                sp.csc_matrix(qp.constraint_matrix),
                np.concatenate([-qp.step_limit, qp.input_lo]), np.concatenate([qp.step_limit, qp.input_hi]),
                eps_abs=qp.config.osqp_eps, eps_rel=qp.config.osqp_eps, polishing=False, verbose=False,
                warm_starting=True, max_iter=4000,
            )
            self._solver = solver
        return self._solver

    def solve_constrained(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, bool]:
        """The condensed QP with this step's terms (:func:`constrained_terms`): (du, ok); du is zero when the
        solver failed."""
        if self.qp.config.qp_solver == "daqp":
            x, ok = self._daqp(q, lower, upper)
        else:
            solver = self._osqp()
            solver.update(q=q, l=lower, u=upper)
            result = solver.solve(raise_error=False)
            x, ok = result.x, result.info.status_val in (1, 2) and result.x is not None
        ok = ok and bool(np.all(np.isfinite(x)))
        step_limit = self.qp.step_limit
        return (np.clip(x, -step_limit, step_limit) if ok else np.zeros(len(step_limit))), ok

    def _daqp(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, bool]:
        """DAQP: the first 2 Nc limits are bounds on du, the rest rows of the cumulative-sum matrix."""
        qp = self.qp
        x, _, exitflag, _ = daqp.solve(qp.hessian, q, qp.cumsum, upper, lower, qp.daqp_sense)
        return np.asarray(x), exitflag > 0

    def solve(self, z_now: np.ndarray, z_ref: np.ndarray, disturbance: np.ndarray) -> MpcSolution:
        """Optimal increments (the closed loop does the same with the compiled parts directly).

        Args:
            z_now: the QP's state (:meth:`ReferenceQp.pack_state`), the last two entries being the previous commands.
            z_ref: reference [V, beta, r, delta, Fxr kN].
            disturbance: estimated additive disturbance on (Vdot, betadot, rdot).
        """
        qa = self.qp.arrays
        z_now, z_ref, disturbance = (np.asarray(v, float) for v in (z_now, z_ref, disturbance))
        ref_gain_term, ref_linear_term = reference_terms(qa, z_ref)
        du, dz, offset, within = unconstrained_increments(qa, z_now, ref_gain_term, disturbance)
        ok = True
        if not within:
            du, ok = self.solve_constrained(*constrained_terms(qa, dz, disturbance, ref_linear_term, offset))
        steer, drive_kn = next_commands(qa, z_now[-N_U:].copy(), du)
        return MpcSolution(steer, drive_kn / KN, not within, ok, du)
