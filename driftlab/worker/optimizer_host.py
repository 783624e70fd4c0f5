"""Jobs' optimizers in a process beside the server's (DRIFTLAB_OPTIMIZER_PROCESS=1): ask and tell run there, the job
loop only sends thetas and values.

An ask is the Bayesian optimizer's whole work (the GP's hyperparameters fitted, the acquisition maximized from many
starts): 20 ms to 0.7 s of Python. On a thread of the server it held the one interpreter that also answers every
request; in a 30-client load with one job running it was 19% of what held the server's interpreter. Here it runs on
another core. Every running job's optimizer lives in the one host process, keyed by a name of its own; the calls
are the same as on a local optimizer, in the same order, with the same arguments, so a job asks what it asked in
the server's thread (the host inherits the server's environment, and with it the BLAS thread count).

If the host dies, the next call starts a new one and restores the optimizer from what was told so far, as a job
resumed after a crash is (:func:`restore_optimizer`, which the job loop uses on its own thread too).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import uuid
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from driftlab.core.optimizer import BayesianOptimizer
from driftlab.core.tuning import TuningSpec
from driftlab.worker.child_process import follow_parent

History = list[tuple[dict[str, float], float | None, float]]

def restore_optimizer(spec: TuningSpec, history: list[tuple[dict[str, float], float | None, float]]
                      ) -> BayesianOptimizer:
    """An optimizer in the state it had after telling ``history`` (theta, J or None if failed, the stored J), told
    first what the job's warm start takes from jobs of its own config (driftlab.core.warm_start)."""
    optimizer = BayesianOptimizer(spec.bounds, **spec.optimizer_options)
    for observation in spec.warm_start.told if spec.warm_start is not None else ():
        optimizer.tell(observation.theta, observation.value, observation.stored_j)
    for theta, value, stored_j in history:
        optimizer.tell(theta, value, stored_j)
    return optimizer


# In the host process: the optimizers of the jobs it serves.
_OPTIMIZERS: dict[str, Any] = {}


def _open(key: str, spec_doc: dict[str, Any], history: History) -> None:
    _OPTIMIZERS[key] = restore_optimizer(TuningSpec.from_dict(spec_doc), history)


def _ask(key: str) -> dict[str, float]:
    return _OPTIMIZERS[key].ask()


def _tell(key: str, theta: dict[str, float], value: float | None, stored_j: float) -> None:
    _OPTIMIZERS[key].tell(theta, value, stored_j)


def _close(key: str) -> None:
    _OPTIMIZERS.pop(key, None)


def _init_host(niceness: int, parent_pid: int) -> None:
    if niceness:
        os.nice(niceness)
    # The host may be (re)started from a job's thread, which ends with its job: no kernel signal (it follows the
    # starting thread), the watcher alone (an ask runs Python, so the watcher gets its turn within 0.5 s).
    follow_parent(parent_pid, kernel_signal=False)


class OptimizerHost:
    """The process that holds the running jobs' optimizers (started with the runner, :meth:`start`; spawned: the
    server has threads, and a fork would copy their locks)."""

    def __init__(self, niceness: int = 0) -> None:
        """``niceness`` > 0 lowers the host's CPU priority (a job's work, below the requests the server answers)."""
        self.niceness = niceness
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()

    def start(self) -> None:
        """Start the host process now (else the first job's first ask waits ~1 s for it)."""
        self.call(os.getpid)

    def open(self, spec: TuningSpec, history: History) -> RemoteOptimizer:
        """The job's optimizer, in the state it had after telling ``history``."""
        optimizer = RemoteOptimizer(self, spec.to_dict(), list(history))
        optimizer.restore()
        return optimizer

    def call(self, fn, *args) -> Any:
        return self.current_pool().submit(fn, *args).result()

    def replace_broken(self, broken: ProcessPoolExecutor) -> None:
        with self._lock:
            if self._pool is broken:
                self._pool = None
        broken.shutdown(wait=False, cancel_futures=True)

    def shutdown(self) -> None:
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def current_pool(self) -> ProcessPoolExecutor:
        with self._lock:
            if self._pool is None:
                self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=_init_host, initargs=(self.niceness, os.getpid()))
            return self._pool


class RemoteOptimizer:
    """A job's optimizer in the host: ask and tell as on driftlab.core.optimizer.BayesianOptimizer."""

    def __init__(self, host: OptimizerHost, spec_doc: dict[str, Any], history: History) -> None:
        self._host, self._spec_doc, self._told = host, spec_doc, history
        self._key = uuid.uuid4().hex

    def restore(self) -> None:
        self._host.call(_open, self._key, self._spec_doc, self._told)

    def ask(self) -> dict[str, float]:
        return self._call(_ask, self._key)

    def tell(self, theta: dict[str, float], value: float | None, stored_j: float) -> None:
        self._call(_tell, self._key, theta, value, stored_j)
        self._told.append((theta, value, stored_j))

    def close(self) -> None:
        try:
            self._host.call(_close, self._key)
        except (BrokenProcessPool, RuntimeError):
            pass  # the host is gone or shut down, and this optimizer with it

    def _call(self, fn, *args) -> Any:
        pool = self._host.current_pool()
        try:
            return pool.submit(fn, *args).result()
        except BrokenProcessPool:
            self._host.replace_broken(pool)
            self.restore()
            return self._host.call(fn, *args)
