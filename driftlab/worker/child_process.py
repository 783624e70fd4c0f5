"""A worker process that dies with its parent: the episode workers and the optimizer host of a server killed with
kill -9 (no cleanup runs) must not live on as orphans holding cores."""

from __future__ import annotations

import os
import signal
import threading
import time


def _exit_with_parent(parent_pid: int, period_s: float = 0.5) -> None:
    """A worker whose parent died (kill -9 included: no cleanup ran) exits within ``period_s`` instead of
    living on as an orphan; it notices by being re-parented."""
    while True:
        time.sleep(period_s)
        if os.getppid() != parent_pid:
            os._exit(0)


def _die_with_parent() -> None:
    """Linux: the kernel kills this process the moment its parent dies (PR_SET_PDEATHSIG), even while a compiled
    episode holds the interpreter and the watcher thread below cannot run."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux: the watcher thread alone


def follow_parent(parent_pid: int, *, kernel_signal: bool = True) -> None:
    """Called first in the worker (a pool's initializer): it exits when ``parent_pid`` does. ``kernel_signal``
    also asks the kernel to kill it at once; that signal follows the parent *thread* that started the worker, so
    a pool whose workers may be started from a short-lived thread must go without it (the watcher alone)."""
    if kernel_signal:
        _die_with_parent()
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(0)
    threading.Thread(target=_exit_with_parent, args=(parent_pid,), name="exit-with-parent", daemon=True).start()
