"""The server's background worker: runs queued jobs one at a time; episodes run in worker processes.

On start it re-queues jobs left "running" by a server that died; they continue from their stored
evaluations (see :mod:`driftlab.worker.job_loop`).
"""

from __future__ import annotations

import threading

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from driftlab.db import storage
from driftlab.db.models import Job
from driftlab.worker.executor import LocalProcessExecutor
from driftlab.worker.job_loop import run_job


class JobWorker:
    def __init__(self, factory: sessionmaker[Session], workers: int = 2, poll_s: float = 0.2) -> None:
        self.factory = factory
        self.workers = workers
        self.poll_s = poll_s
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self._executor: LocalProcessExecutor | None = None
        self.current_job_id: int | None = None

    def start(self) -> None:
        with storage.transaction(self.factory) as session:
            for job in session.scalars(select(Job).where(Job.status == "running")):
                job.status = "queued"
        # Below the what-if worker and the web server in priority: a slider must not wait behind a job.
        self._executor = LocalProcessExecutor(self.workers, niceness=10)
        self._thread = threading.Thread(target=self._loop, name="driftlab-worker", daemon=True)
        self._thread.start()

    def wake(self) -> None:
        self._wake.set()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        if self._executor is not None:
            self._executor.shutdown()

    def _next_job(self) -> int | None:
        with storage.transaction(self.factory) as session:
            return session.scalar(select(Job.id).where(Job.status == "queued").order_by(Job.id).limit(1))

    def _should_stop(self, job_id: int) -> bool:
        if self._stop.is_set():
            return True
        with storage.transaction(self.factory) as session:
            return storage.get_job(session, job_id=job_id).status == "paused"

    def _loop(self) -> None:
        while not self._stop.is_set():
            job_id = self._next_job()
            if job_id is None:
                self._wake.wait(self.poll_s)
                self._wake.clear()
                continue
            self.current_job_id = job_id
            try:
                status = run_job(self.factory, job_id, self._executor, workers=self.workers,
                                 should_stop=lambda jid=job_id: self._should_stop(jid))
                if self._stop.is_set() and status == "paused":
                    # Server shutting down mid-job: leave it to be resumed on the next start.
                    with storage.transaction(self.factory) as session:
                        job = storage.get_job(session, job_id=job_id)
                        if job.status == "paused":
                            job.status = "queued"
            finally:
                self.current_job_id = None
