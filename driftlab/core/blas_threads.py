"""One BLAS thread wherever an episode computes, whatever the process's thread settings.

OpenBLAS splits a matrix product over its threads and sums the partial products in another order, so the
same episode gave J -0.8422037716183076 with two threads and ...151 with one (the condensed QPs are built with
``@`` and ``cho_solve``; the compiled loop calls BLAS through numba's ``np.dot``). An episode is a pure
function of (theta, config, seed), so the thread count must not be an input: :func:`one_blas_thread` pins
it for the episode and gives the process's own setting back afterwards.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TypeVar

from threadpoolctl import ThreadpoolController

_lock = threading.Lock()
_depth = 0
_controller: ThreadpoolController | None = None
_restore = None

F = TypeVar("F", bound=Callable)


def _pool_controller() -> ThreadpoolController:
    # Built once: scanning the loaded libraries costs ~1 ms, a limit on a known controller ~15 us.
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS limited to one thread inside the block; nested and concurrent blocks share one limit, lifted when
    the last of them ends (the limit is process-wide, so a thread must not lift it under another's episode)."""
    global _depth, _restore
    with _lock:
        if _depth == 0:
            _restore = _pool_controller().limit(limits=1, user_api="blas")
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _restore is not None:
                _restore.restore_original_limits()
                _restore = None


def with_one_blas_thread(function: F) -> F:
    """Decorator form of :func:`one_blas_thread`."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return function(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
