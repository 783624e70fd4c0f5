"""The processes a server or a CLI starts (episode workers, optimizer hosts): how they start, and that they die with
the process that owns them (a server killed with kill -9 runs no cleanup, and they must not live on as orphans
holding cores)."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time

# What every worker imports: the forkserver imports it once, and each worker is forked with it already loaded.
# Not the optimizer's scikit-learn (~1.5 s): optimizer processes are off by default (driftlab.settings).
PRELOADED = ("driftlab.worker.executors.episode", "driftlab.worker.optimizer_host")


def worker_context() -> multiprocessing.context.BaseContext:
    """Workers are forked from multiprocessing's forkserver, which imported :data:`PRELOADED` once: a spawned worker
    imported NumPy, SciPy, numba and DriftLab anew, ~0.7 s of a core each before its first episode (three a server).
    Not forked from the server itself: it has threads, and a fork would copy their locks. The forkserver has one
    thread and exits when its owner does (its end of a pipe closes), and with it, through the kernel's signal, every
    worker forked from it. It inherits the owner's environment at its start: one BLAS thread is set first (BLAS
    oversubscription on 2 cores cost up to 8x)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(PRELOADED))
    return context


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # it exists, under another user
    return True


def _exit_with_owner(owner_pid: int, parent_pid: int, period_s: float = 0.5) -> None:
    """A worker whose owner died (kill -9 included: no cleanup ran) exits within ``period_s`` instead of living on
    as an orphan; it notices by being re-parented (its forkserver ended) or by the owner being gone."""
    while True:
        time.sleep(period_s)
        if os.getppid() != parent_pid or not _alive(owner_pid):
            os._exit(0)


def _die_with_parent() -> None:
    """Linux: the kernel kills this process the moment its parent (the forkserver, which ends with the owner) dies
    (PR_SET_PDEATHSIG), even while a compiled episode holds the interpreter and the watcher thread cannot run."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux: the watcher thread alone


def follow_owner(owner_pid: int) -> None:
    """Called first in a worker started from :func:`worker_context` (a pool's initializer): it exits when
    ``owner_pid`` (the server or CLI that started it) does. The kernel's signal follows the forkserver's one
    thread, which lives as long as the owner, whichever of the owner's threads asked for the worker."""
    _die_with_parent()
    parent_pid = os.getppid()
    if not _alive(owner_pid):  # the owner died before the signal was armed
        os._exit(0)
    threading.Thread(target=_exit_with_owner, args=(owner_pid, parent_pid), name="exit-with-owner",
                     daemon=True).start()
