"""How the long-running commands stop (an edge, beside the CLI)."""

from __future__ import annotations

import signal
import threading

_terminated = threading.Event()


def stop_on_sigterm() -> None:
    """SIGTERM (docker stop, timeout, systemd) stops like Ctrl-C: the job is paused, its lease released, the worker
    processes shut down, instead of the lease going stale for 15 s and semaphores leaking."""

    def interrupt(_signum, _frame):
        _terminated.set()
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)


def raise_if_terminated() -> None:
    """KeyboardInterrupt once SIGTERM came. The handler's own raise is lost where the signal lands in a finalizer
    (llvmlite's ``ObjectRef.__del__``): Python prints an exception raised there and goes on. Called at each
    evaluation, this stops the run one evaluation later."""
    if _terminated.is_set():
        raise KeyboardInterrupt


def stop_if_terminated() -> bool:
    """A ``should_stop`` for the loops that poll one (a robustness study's, driftlab.worker.study_runner): raises
    as :func:`raise_if_terminated` does, on the loop's own thread, where Ctrl-C would land; False otherwise."""
    raise_if_terminated()
    return False
