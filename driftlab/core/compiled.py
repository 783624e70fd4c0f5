"""Whether the episode loop's compiled kernels are in numba's on-disk cache (or must compile first).

The first episode after an install compiles the loop (measured 20-105 s on 2 cores, quiet to loaded); every later
process loads it from the cache in about a second. A job's status says "compiling" while this is False so that
nobody kills a job that is only compiling.
"""

from __future__ import annotations


def _indexed(dispatcher) -> bool:
    # numba's cache index is keyed by the source file's stamp: after a reinstall or an edit it reads as empty.
    return bool(dispatcher._cache._cache_file._load_index())


# Only True is remembered: once written, the cache stays valid for the source files this process runs.
_known_cached = False


def episode_kernels_cached() -> bool | None:
    """True if the closed loop's kernels load from the on-disk cache, False if the next episode compiles them,
    None if numba's cache cannot be read (its private index API changed)."""
    global _known_cached
    if _known_cached:
        return True
    try:
        from driftlab.core.closed_loop import finish_step, run_until_constrained

        _known_cached = all(_indexed(d) for d in (run_until_constrained, finish_step))
    except (AttributeError, OSError, ImportError):
        return None
    return _known_cached
