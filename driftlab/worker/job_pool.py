"""Jobs run side by side on one executor: each on a thread of its own with its own optimizer, the executor's capacity
shared among them (driftlab.worker.slots), so at most as many jobs at once as it has workers. The one scheduler of
jobs: the server's runner (driftlab.worker.job_runner) starts the jobs it claims here, ``driftlab study`` a seeds
study's jobs."""

from __future__ import annotations

import threading
from collections.abc import Callable

from sqlalchemy.orm import Session, sessionmaker

from driftlab.worker.executors import EpisodeExecutor
from driftlab.worker.job_loop import run_job
from driftlab.worker.optimizer_host import OptimizerHost
from driftlab.worker.slots import EpisodeSlots


class JobPool:
    """Args:
        runner: the lease every job started here is held under (the caller claims them first).
        should_stop: asked by every job between evaluations (the runner shuts down: each job goes back to the
            queue after what is in flight).
        on_done: called on the job's thread with (job id, the status it left the job in) once its share is free.
        daemon: the jobs' threads end with the process (the server's runner stops them itself); a command's keep
            it alive until they are done.
    """

    def __init__(self, factory: sessionmaker[Session], executor: EpisodeExecutor, slots: EpisodeSlots, *,
                 runner: str, should_stop: Callable[[], bool], max_trajectories: int,
                 optimizers: OptimizerHost | None = None,
                 on_done: Callable[[int, str | None], None] = lambda job_id, status: None,
                 daemon: bool = True) -> None:
        self.factory, self.executor, self.slots, self.runner = factory, executor, slots, runner
        self.should_stop, self.max_trajectories, self.optimizers = should_stop, max_trajectories, optimizers
        self.on_done, self.daemon = on_done, daemon
        self.statuses: dict[int, str] = {}  # the status each finished run left its job in
        self._threads: dict[int, threading.Thread] = {}
        self._lock = threading.Lock()

    @property
    def running(self) -> list[int]:
        with self._lock:
            return sorted(self._threads)

    @property
    def free(self) -> int:
        """How many more jobs may start now (each takes at least one of the executor's slots)."""
        return self.slots.capacity - len(self.running)

    def start(self, job_ids: list[int]) -> None:
        """Runs jobs ``runner`` holds, each on its thread: every one of them has its share before any of them
        asks."""
        for job_id in job_ids:
            self.slots.join(job_id)
        for job_id in job_ids:
            thread = threading.Thread(target=self._run, args=(job_id,), name=f"driftlab-job-{job_id}",
                                      daemon=self.daemon)
            with self._lock:
                self._threads[job_id] = thread
            thread.start()

    def join(self, timeout_s: float | None = None) -> None:
        """Until every job started here has stopped (each at most ``timeout_s``)."""
        with self._lock:
            threads = list(self._threads.values())
        for thread in threads:
            thread.join(timeout=timeout_s)

    def _run(self, job_id: int) -> None:
        status = None
        try:
            status = self.statuses[job_id] = run_job(
                self.factory, job_id, self.executor, runner=self.runner, slots=self.slots, owner=job_id,
                should_stop=self.should_stop, optimizers=self.optimizers, max_trajectories=self.max_trajectories)
        finally:
            with self._lock:
                self._threads.pop(job_id, None)
            self.on_done(job_id, status)
