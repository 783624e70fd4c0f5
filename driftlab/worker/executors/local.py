"""Episodes in local worker processes (from a forkserver, one BLAS thread each, dying with their owner)."""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any

from driftlab.worker.child_process import follow_owner, worker_context
from driftlab.worker.executors.episode import EpisodeOutcome, evaluate_episode


def _init_worker(niceness: int, owner_pid: int) -> None:
    if niceness:
        os.nice(niceness)
    follow_owner(owner_pid)


class LocalProcessExecutor:
    """Episodes in separate processes (never in the caller's thread or event loop)."""

    def __init__(self, workers: int = 1, *, niceness: int = 0) -> None:
        """``niceness`` > 0 lowers the workers' CPU priority (batch work that must not slow interactive work)."""
        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=worker_context(),
                                        initializer=_init_worker, initargs=(niceness, os.getpid()))
        # Start every worker now, but not on this thread: the first start waits for the forkserver's imports
        # (~0.7 s of a core), which the caller's own start-up overlaps.
        threading.Thread(target=self._start_workers, name="episode-workers-start", daemon=True).start()

    def _start_workers(self) -> None:
        try:
            for _ in range(self.workers):
                self.pool.submit(os.getpid)
        except RuntimeError:
            pass  # shut down before they started

    def submit(self, theta: dict[str, float], config_doc: dict[str, Any], seed: int = 0) -> Future[EpisodeOutcome]:
        return self.pool.submit(evaluate_episode, theta, config_doc, seed)

    def warm_up(self) -> Future[EpisodeOutcome]:
        """Start the workers and load the compiled dynamics now, so the first real episode is not slow."""
        futures = [self.pool.submit(evaluate_episode, {}, {"scenario": {"max_time_s": 1.0}})
                   for _ in range(self.workers)]
        return futures[-1]

    def shutdown(self) -> None:
        """Ends the workers at once: an episode in flight is dropped (whoever takes its work up runs it again), as
        a stop within Docker's 10 s grace needs; waiting for it took up to an episode's time on a loaded machine."""
        processes = list((self.pool._processes or {}).values())  # the pool has no public terminate before 3.14
        results = self.pool._result_queue
        self.pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()
        for process in processes:
            process.join(timeout=5)
        if results is not None and not any(process.is_alive() for process in processes):
            # A worker ended mid-result leaves the pool's manager thread (joined at exit) reading the rest for ever:
            results._writer.close()  # ours is the last writing end, and closing it ends that read
