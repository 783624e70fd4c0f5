"""How the long-running commands stop (an edge, beside the CLI)."""

from __future__ import annotations

import signal


def stop_on_sigterm() -> None:
    """SIGTERM (docker stop, timeout, systemd) stops like Ctrl-C: the job is paused, its lease released, the worker
    processes shut down, instead of the lease going stale for 15 s and semaphores leaking."""

    def interrupt(_signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)
