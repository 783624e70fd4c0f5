"""Episodes on a Dask cluster: the executor protocol (submit -> Future, shutdown) over ``distributed.Client``.

Every episode is a pure function of (theta, config, seed), so Dask may run it anywhere and again: a worker
lost mid-episode has its tasks rescheduled by the scheduler on another worker (up to the scheduler's
``allowed-failures``), and an exception is retried ``retries`` times. The job loop still decides what is
stored, once, when an evaluation's episodes are all back: no evaluation is lost or stored twice.

The futures handed out are :class:`concurrent.futures.Future`, so the job loop waits on a Dask cluster as on
the local pool; the Dask future behind each is held until it resolves (a released Dask future cancels its
task).
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future
from typing import Any

from driftlab.worker.executors.episode import EpisodeOutcome, evaluate_episode

RECONNECT_EVERY_S = 3.0


class SchedulerUnreachable(ConnectionError):
    """The Dask scheduler does not answer (the job pauses; it resumes when the scheduler is back)."""


class DaskExecutor:
    def __init__(self, address: str, *, retries: int = 2, connect_timeout_s: float = 10.0) -> None:
        import distributed  # noqa: F401  (its import configures its loggers: quiet them after it)

        # A lost scheduler is reported once, by the job (paused, with the reason); the client's own reconnect
        # attempts would print a traceback each.
        for name in ("distributed.client", "distributed.comm", "distributed.core", "distributed.batched"):
            logging.getLogger(name).setLevel(logging.CRITICAL)
        self.address = address
        self.client = self._connect(connect_timeout_s)
        self._last_attempt = time.monotonic()
        self.retries = retries
        self._pending: dict[int, Any] = {}
        self._lock = threading.Lock()
        self._capacity = 1

    def _connect(self, timeout_s: float):
        from distributed import Client

        try:
            return Client(self.address, timeout=timeout_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise SchedulerUnreachable(f"no Dask scheduler at {self.address}: {exc}") from None

    @property
    def connected(self) -> bool:
        """Whether the client talks to its scheduler now. A client that gave up after an outage is replaced
        by a new one, tried at most every RECONNECT_EVERY_S (from the job runner's thread, never the server's
        event loop)."""
        if self.client.status == "running":
            return True
        if time.monotonic() - self._last_attempt < RECONNECT_EVERY_S:
            return False
        self._last_attempt = time.monotonic()
        try:
            fresh = self._connect(2.0)
        except SchedulerUnreachable:
            return False
        old, self.client = self.client, fresh
        old.close()
        return True

    @property
    def workers(self) -> int:
        """Worker threads in the cluster now (a job's default batch size)."""
        return self.capacity()

    def capacity(self) -> int:
        """Worker threads in the cluster now (one round trip to the scheduler): workers joining (``cluster.adapt``,
        a ``dask worker`` started) and leaving change it. While the scheduler is away, the last count."""
        if self.client.status == "running":
            try:
                self._capacity = max(sum(self.client.nthreads().values()), 1)
            except (OSError, TimeoutError):
                pass
        return self._capacity

    def submit(self, theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> Future[EpisodeOutcome]:
        result: Future[EpisodeOutcome] = Future()
        dask_future = self.client.submit(evaluate_episode, theta, config_doc, seed, pure=False,
                                         retries=self.retries)
        key = id(result)
        with self._lock:
            self._pending[key] = dask_future

        def resolve(done) -> None:
            with self._lock:
                self._pending.pop(key, None)
            try:
                result.set_result(done.result())
            except Exception as exc:  # the episode raised after its retries, or the cluster lost it
                result.set_exception(exc)

        dask_future.add_done_callback(resolve)
        return result

    def shutdown(self) -> None:
        with self._lock:
            pending = list(self._pending.values())
            self._pending.clear()
        for future in pending:
            future.cancel()
        self.client.close()
