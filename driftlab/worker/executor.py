"""Where episodes run: one small interface, a local process pool today.

A distributed engine (Dask's ``Client.submit`` returns compatible futures) can take the place of
:class:`LocalProcessExecutor` by implementing :class:`EpisodeExecutor`.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from driftlab.core.robust import SampleResult


@dataclass
class EpisodeOutcome:
    """What a worker process sends back: everything storage needs, as plain data."""

    theta: dict[str, float]
    seed: int
    status: str
    J: float
    metrics: dict[str, Any]
    trigger_points: list[dict[str, float]]
    wall_ms: float
    columns: list[str]
    trajectory: np.ndarray

    @property
    def completed(self) -> bool:
        return self.status == "completed"

    def sample(self) -> SampleResult:
        """This episode as one sample of a robust evaluation."""
        error = self.metrics.get("mean_abs_e_m")
        return SampleResult(self.seed, self.status, float(self.J), float(self.metrics.get("completed_fraction", 0.0)),
                            float(error) if error is not None and math.isfinite(error) else None)


class EpisodeExecutor(Protocol):
    def submit(self, theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> Future[EpisodeOutcome]:
        ...

    def shutdown(self) -> None: ...


def evaluate_episode(theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> EpisodeOutcome:
    """Runs in the worker process. A pure function of its arguments (see run_episode)."""
    from driftlab.core.config import Theta, config_from_dict
    from driftlab.core.episode import COLUMNS, run_episode

    result = run_episode(Theta.from_mapping(theta), config_from_dict(config_doc), seed=seed)
    return EpisodeOutcome(theta=dict(theta), seed=seed, status=result.status, J=float(result.J),
                          metrics=result.metrics.as_dict(), trigger_points=result.trigger_points,
                          wall_ms=float(result.wall_ms), columns=list(COLUMNS), trajectory=result.trajectory)


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


def _init_worker(niceness: int, parent_pid: int) -> None:
    # BLAS oversubscription on 2 cores costs up to 8x.
    os.environ["OMP_NUM_THREADS"] = "1"
    if niceness:
        os.nice(niceness)
    _die_with_parent()
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(0)
    threading.Thread(target=_exit_with_parent, args=(parent_pid,), name="exit-with-parent", daemon=True).start()


class LocalProcessExecutor:
    """Episodes in separate processes (never in the caller's thread or event loop)."""

    def __init__(self, workers: int = 1, *, niceness: int = 0) -> None:
        """``niceness`` > 0 lowers the workers' CPU priority (batch work that must not slow interactive work)."""
        os.environ.setdefault("OMP_NUM_THREADS", "1")
        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                        initializer=_init_worker, initargs=(niceness, os.getpid()))

    def submit(self, theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> Future[EpisodeOutcome]:
        return self.pool.submit(evaluate_episode, theta, config_doc, seed)

    def warm_up(self) -> Future[EpisodeOutcome]:
        """Start the workers and load the compiled dynamics now, so the first real episode is not slow."""
        futures = [self.pool.submit(evaluate_episode, {}, {"scenario": {"max_time_s": 1.0}})
                   for _ in range(self.workers)]
        return futures[-1]

    def shutdown(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


def open_executor(workers: int | None, dask_address: str | None = None, *, niceness: int = 0
                  ) -> tuple[EpisodeExecutor, int]:
    """The local process pool, or a Dask cluster by address; and how many episodes to keep in flight (given,
    or the cluster's worker threads; 1 locally by default)."""
    if dask_address:
        from driftlab.worker.dask_executor import DaskExecutor

        executor = DaskExecutor(dask_address)
        return executor, workers or executor.workers
    return LocalProcessExecutor(workers or 1, niceness=niceness), workers or 1
