"""The linear MPC drift controller (paper section II-B), condensed and solved with OSQP.

Augmented state z = [V, beta, r, delta, Fxr] with Fxr in kN (in newtons OSQP needs thousands of iterations,
docs/reference.md, The QP's units), inputs the increments [d_delta, d_Fxr]. The model is linearized about the reference
drift equilibrium and discretized (forward Euler as in the paper, or exact zero-order hold). Cost:
sum_{k=1..Np} ||z_k - z_ref||_Q^2 + sum_{k=0..Nc-1} ||du_k||_R^2 (paper eq. 7), Np = Nc, box limits on
delta, Fxr and both increments.

Solving: the QP is condensed to the 2*Nc increments once per reference. Each step first forms the
unconstrained minimizer with a precomputed gain; when it satisfies every limit it *is* the QP's solution
(the constraints are inactive, the QP is strictly convex). Only otherwise (about one step in twenty) a solver
runs, chosen by ``qp_solver``:

- ``daqp`` (default): DAQP's dual active-set method (Arnstroem, Bemporad & Axehill 2022), exact for this dense
  40-variable QP, ~60 us a solve with the call.
- ``osqp``: OSQP (the paper's solver; set up once per episode, warm-started within it, only q, l, u updated) at
  ``osqp_eps``, ~600 us a solve. Its accepted answers include "solved inaccurate": on the default plant they
  sat up to 0.64 (rad or kN) from the exact increments, some beyond a limit. Jobs stored before revision 7
  ran it and stay on it. OSQP's polishing is off: OSQP 1.x prints an unguarded line on stdout per polish
  (osqp/osqp#785), which would corrupt the CLI's JSON.

Offset-free extension (not in the paper; ``disturbance_gain`` > 0): a constant additive disturbance d on
(Vdot, betadot, rdot) is estimated each step from the difference between the measured state and the
controller model's one-step prediction, and enters the prediction (Maeder, Borrelli & Morari 2009).

The package, one concept a module: ``config`` (settings, units, sizes), ``model`` (the augmented, discretized
prediction model), ``condensing`` (the QP for one reference), ``kernels`` (the compiled per-step pieces),
``estimator`` (the offset-free disturbance estimate), ``session`` (one episode's solver), ``arrays`` (what a step
returns and what the compiled loop reads).
"""

from driftlab.core.mpc.arrays import MpcSolution, QpArrays
from driftlab.core.mpc.condensing import ReferenceQp
from driftlab.core.mpc.estimator import update_estimate
from driftlab.core.mpc.kernels import (
    clip,
    constrained_terms,
    next_commands,
    pack_state,
    reference_gain_term,
    reference_linear_term,
    reference_terms,
    unconstrained_increments,
)
from driftlab.core.mpc.model import discretize, scale_inputs, to_scaled
from driftlab.core.mpc.session import QpSession
from driftlab.core.mpc_config import KN, N_PER_KN, N_U, N_X, N_Z, MpcConfig

__all__ = ["KN", "N_PER_KN", "N_U", "N_X", "N_Z", "MpcConfig", "MpcSolution", "QpArrays", "QpSession", "ReferenceQp",
           "clip", "constrained_terms", "discretize", "next_commands", "pack_state", "reference_gain_term",
           "reference_linear_term", "reference_terms", "scale_inputs",
           "to_scaled", "unconstrained_increments", "update_estimate"]
