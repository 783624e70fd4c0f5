"""The one table of a tuning job's integer settings and their allowed ranges, shared by the REST API's request
schema, :class:`driftlab.core.tuning.TuningSpec`, the CLI and the optimizer (each used to keep its own).
"""

from __future__ import annotations

from driftlab.core.errors import ConfigError

# Episodes per evaluation by default: with 4 seeds a theta that fails one run in ten still fails an evaluation
# 34% of the time, enough for the failure model to steer away from it, at 4x the episodes (2 workers keep
# one evaluation in flight, so the BO stays sequential).
DEFAULT_ROBUST_SAMPLES = 4
# Extra seeds a would-be best evaluation must also complete (see driftlab.worker.job_loop).
DEFAULT_CONFIRM_SAMPLES = 4
MAX_GRID = 60  # points per axis of a search-space surface (GET /api/jobs/{id}/search-space)
MAX_ROBUST_SAMPLES = 64  # also the block of episode seeds each BO seed owns (driftlab.core.robust)

JOB_LIMITS: dict[str, tuple[int, int]] = {
    "iterations": (1, 5000),
    "seed_points": (1, 1000),
    "active_set": (10, 5000),
    "seed": (0, 2**31 - 1),
    "robust_samples": (1, MAX_ROBUST_SAMPLES),
    "confirm_samples": (0, MAX_ROBUST_SAMPLES - 1),
}


def check_int(name: str, value: object, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as an int within ``JOB_LIMITS[name]`` (or the given range); a bool or float is an error."""
    default_lo, default_hi = JOB_LIMITS.get(name, (lo, hi))
    lo = default_lo if lo is None else lo
    hi = default_hi if hi is None else hi
    if lo is None or hi is None:
        raise ValueError(f"no range for {name!r}: give lo and hi")
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return value
