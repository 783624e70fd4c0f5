"""DAQP called from the compiled loop: the C function ``daqp.solve`` calls, with the arguments it passes.

A step whose unconstrained minimizer breaks a limit (about one in twenty) is solved without leaving the kernel: a
return to Python and back costs ~20 us (numba unboxing the loop's settings and arrays), and ``daqp.solve``'s own
wrapper ~45 us of a ~70 us solve. The kernel calls ``daqp_quadprog`` itself,
through its address in the binding, on structs laid out as the binding's C sources (daqp 0.11.0, csrc/include/types.h
and api.h) lay them out and filled as ``daqp.solve`` fills them: the same setup, the same solve, the same bits
(tests/core/test_daqp_kernel.py compares x and the exit flag with ``daqp.solve``). Another daqp release may lay the
structs out otherwise: :func:`quadprog_address` is then 0 and the loop returns to Python as before.
"""

from __future__ import annotations

import ctypes
from functools import cache
from importlib.metadata import PackageNotFoundError, version

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.extending import intrinsic

_LAID_OUT_FOR = "0.11.0"  # the daqp release whose C structs these are


class _Problem(ctypes.Structure):
    _fields_ = [("n", ctypes.c_int), ("m", ctypes.c_int), ("ms", ctypes.c_int),
                ("H", ctypes.c_void_p), ("f", ctypes.c_void_p), ("A", ctypes.c_void_p),
                ("bupper", ctypes.c_void_p), ("blower", ctypes.c_void_p), ("sense", ctypes.c_void_p),
                ("break_points", ctypes.c_void_p), ("nh", ctypes.c_int), ("problem_type", ctypes.c_int)]


class _Settings(ctypes.Structure):
    _fields_ = [("primal_tol", ctypes.c_double), ("dual_tol", ctypes.c_double), ("zero_tol", ctypes.c_double),
                ("pivot_tol", ctypes.c_double), ("progress_tol", ctypes.c_double), ("cycle_tol", ctypes.c_int),
                ("iter_limit", ctypes.c_int), ("fval_bound", ctypes.c_double), ("eps_prox", ctypes.c_double),
                ("eta_prox", ctypes.c_double), ("rho_soft", ctypes.c_double), ("rel_subopt", ctypes.c_double),
                ("abs_subopt", ctypes.c_double), ("sing_tol", ctypes.c_double), ("refactor_tol", ctypes.c_double),
                ("time_limit", ctypes.c_double), ("w_soft", ctypes.c_double), ("eq_reduction", ctypes.c_int),
                ("presolve", ctypes.c_int)]


class _Result(ctypes.Structure):
    _fields_ = [("x", ctypes.c_void_p), ("lam", ctypes.c_void_p), ("fval", ctypes.c_double),
                ("soft_slack", ctypes.c_double), ("exitflag", ctypes.c_int), ("iter", ctypes.c_int),
                ("nodes", ctypes.c_int), ("solve_time", ctypes.c_double), ("setup_time", ctypes.c_double)]


# daqp.solve's keyword defaults (daqp.pyx 0.11.0, from csrc/include/constants.h), in _Settings' order.
_SOLVE_DEFAULTS = _Settings(primal_tol=1e-6, dual_tol=1e-12, zero_tol=1e-11, pivot_tol=1e-8, progress_tol=1e-14,
                            cycle_tol=10, iter_limit=10000, fval_bound=1e30, eps_prox=-1e-6, eta_prox=-1.0,
                            rho_soft=1e-6, rel_subopt=0.0, abs_subopt=0.0, sing_tol=3.7e-11, refactor_tol=1e-9,
                            time_limit=0.0, w_soft=0.0, eq_reduction=0, presolve=1)
SETTINGS_WORDS = ctypes.sizeof(_Settings) // 8
PROBLEM_WORDS = ctypes.sizeof(_Problem) // 8
RESULT_WORDS = ctypes.sizeof(_Result) // 8
# The settings as 64-bit words, copied into the loop's buffer before each solve (daqp.solve builds them afresh).
SETTINGS = np.frombuffer(bytes(_SOLVE_DEFAULTS), dtype=np.int64).copy()

# Field offsets, in 32- and 64-bit words, for the kernel.
_P_N, _P_M, _P_MS = (getattr(_Problem, f).offset // 4 for f in ("n", "m", "ms"))
_P_H, _P_F, _P_A, _P_BU, _P_BL, _P_SENSE, _P_BP = (getattr(_Problem, f).offset // 8 for f in
                                                   ("H", "f", "A", "bupper", "blower", "sense", "break_points"))
_P_NH, _P_TYPE = (getattr(_Problem, f).offset // 4 for f in ("nh", "problem_type"))
_R_X, _R_LAM = _Result.x.offset // 8, _Result.lam.offset // 8
_R_EXITFLAG = _Result.exitflag.offset // 4


@cache  # looked up once a process
def quadprog_address() -> int:
    """The address of the binding's ``daqp_quadprog``, or 0 where the installed daqp is not the release these
    structs are laid out for (the loop then solves through ``daqp.solve`` in Python)."""
    try:
        if version("daqp") != _LAID_OUT_FOR:
            return 0
        import daqp

        return int(ctypes.cast(ctypes.CDLL(daqp.__file__).daqp_quadprog, ctypes.c_void_p).value or 0)
    except (PackageNotFoundError, ImportError, OSError, AttributeError):
        return 0


@intrinsic
def _call(typingctx, function, result, problem, settings):
    """``function(result, problem, settings)``, a C function of three pointers, by its address."""
    sig = types.void(types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        pointer = ir.IntType(8).as_pointer()
        callee = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [pointer] * 3).as_pointer())
        builder.call(callee, [builder.inttoptr(a, pointer) for a in args[1:]])
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True)
def quadprog(function, hessian, q, constraints, upper, lower, sense, x, lam, problem, result, settings):
    """Exit flag of ``daqp.solve(hessian, q, constraints, upper, lower, sense)``; its solution in ``x`` and the
    multipliers in ``lam``. ``problem``, ``result`` and ``settings`` are int64 buffers of PROBLEM_WORDS,
    RESULT_WORDS and SETTINGS_WORDS words; every array C-contiguous, ``sense`` int32."""
    p32 = problem.view(np.int32)
    problem[:] = 0
    p32[_P_N] = hessian.shape[0]
    p32[_P_M] = upper.shape[0]
    p32[_P_MS] = upper.shape[0] - constraints.shape[0]  # the first rows are bounds on x itself
    problem[_P_H] = hessian.ctypes.data
    problem[_P_F] = q.ctypes.data
    problem[_P_A] = constraints.ctypes.data
    problem[_P_BU] = upper.ctypes.data
    problem[_P_BL] = lower.ctypes.data
    problem[_P_SENSE] = sense.ctypes.data
    problem[_P_BP] = 0  # no hierarchy: nh 0, a plain QP (problem_type 0)
    p32[_P_NH] = 0
    p32[_P_TYPE] = 0
    result[:] = 0
    result[_R_X] = x.ctypes.data
    result[_R_LAM] = lam.ctypes.data
    settings[:] = SETTINGS
    _call(function, result.ctypes.data, problem.ctypes.data, settings.ctypes.data)
    return result.view(np.int32)[_R_EXITFLAG]
