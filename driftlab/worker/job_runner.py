"""The server's background job runner: one thread that claims claimable jobs (queued, or held by a dead runner)
and runs each on a thread of its own, as many at once as the executor has workers; and beside them one robustness
study (driftlab.worker.study_runner), one rescore (driftlab.worker.rescoring) and one calibration
(driftlab.worker.calibrating) at a time, each on a thread of its own: the runner's thread only claims and starts.
Every episode runs on the one executor, whose capacity the running jobs, the study, the rescore and the calibration
share (driftlab.worker.slots): a seeds study's jobs run side by side, each with its own optimizer.

Exactly one runner runs a job at a time (the lease in driftlab.db.lifecycle): a `driftlab tune` on the same
job is refused while this one holds it, and a job this server held when it died is taken over by the next
runner once its lease goes stale.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.statuses import StudyKind
from driftlab.db import lease, lifecycle, storage, studies
from driftlab.db.models import Calibration, Job, Rescore, Study
from driftlab.settings import MAX_TRAJECTORIES_PER_JOB
from driftlab.worker.calibrating import run_stored_calibration
from driftlab.worker.executors import EpisodeExecutor, open_executor
from driftlab.worker.job_loop import EXECUTOR_LOST
from driftlab.worker.job_pool import JobPool
from driftlab.worker.optimizer_host import OptimizerHost
from driftlab.worker.rescoring import run_rescore
from driftlab.worker.slots import EpisodeSlots, capacity_of
from driftlab.worker.study_runner import run_study

# How long a stop waits for the runner's threads to hand their work back themselves; then it hands back what they
# still hold and ends the workers: `docker stop` kills 10 s after SIGTERM, and the server has its database to close.
STOP_WAIT_S = 5.0

# Optimizer processes started with the runner (DRIFTLAB_OPTIMIZER_PROCESS=1): a job beyond them starts its own.
OPTIMIZER_PROCESSES_AT_START = 8


class JobRunner:
    def __init__(self, factory: sessionmaker[Session], workers: int | None = 2, poll_s: float = 0.2,
                 busy_poll_s: float = 1.0, dask_address: str | None = None,
                 max_trajectories_per_job: int = MAX_TRAJECTORIES_PER_JOB, optimizer_process: bool = False) -> None:
        self.factory = factory
        self.workers = workers
        self.dask_address = dask_address
        self.max_trajectories_per_job = max_trajectories_per_job
        # How long the loop waits for a wake (a job ending, a request that queued work) before it looks in the
        # database for work queued elsewhere (another server, the CLI, a runner that died): poll_s while idle,
        # busy_poll_s while jobs run. A look is 4-5 transactions, 2.5-6 ms of the server's CPU, for work that is
        # rarely there; a busy server needs that CPU for its evaluations (benchmarks/bench_concurrency.py).
        self.poll_s, self.busy_poll_s = poll_s, max(poll_s, busy_poll_s)
        self.runner_id = lifecycle.new_runner_id("server")
        self._stop = threading.Event()
        self._stop_by = float("inf")
        self._wake = threading.Event()
        # Set with every wake but a job's end (a request that queued work, a side task that ended, the stop): the
        # loop then looks at every kind of work. A job that ends frees its share for the next job, nothing else,
        # and at 8 jobs on 16 workers the other looks were a quarter of the server's CPU (bench_concurrency.py).
        self._look_everywhere = True
        self._look_lock = threading.Lock()
        # Whether the last claim left claimable jobs behind (it had less room than the queue had jobs): only then can
        # a job's end find one to start. A claim that finds none is a transaction per job's end (8 a seeds study).
        self._jobs_left = True
        self._thread: threading.Thread | None = None
        self._executor: EpisodeExecutor | None = None
        self._slots: EpisodeSlots | None = None
        self._jobs: JobPool | None = None  # the jobs running now, each on its thread
        # The robustness study, the rescore and the calibration running now, if any: kind -> (its id, its thread).
        self._side_tasks: dict[str, tuple[int, threading.Thread]] = {}
        # With optimizer_process, the jobs' asks and tells off the server's interpreter (below the requests in
        # priority, as the episodes); else on each job's thread.
        self._optimizers = OptimizerHost(niceness=10) if optimizer_process else None

    @property
    def optimizers(self) -> OptimizerHost | None:
        """The jobs' optimizer processes (None: the jobs ask on their own threads)."""
        return self._optimizers

    @property
    def current_study_id(self) -> int | None:
        """The robustness study this runner runs now, if any."""
        running = self._side_tasks.get("study")
        return running[0] if running is not None and running[1].is_alive() else None

    @property
    def running_job_ids(self) -> list[int]:
        """The jobs this runner runs now (several at once, up to the executor's capacity)."""
        return [] if self._jobs is None else self._jobs.running

    def start(self, executor: EpisodeExecutor | None = None) -> None:
        """Opens the executor (or takes ``executor``, whose capacity is ``workers``) and starts the runner."""
        given = self.workers
        if executor is None:
            # Below the what-if worker and the web server in priority: a slider must not wait behind a job.
            self._executor, self.workers = open_executor(self.workers, self.dask_address, niceness=10)
        else:
            self._executor, self.workers = executor, self.workers or 1
        self._slots = EpisodeSlots(capacity_of(self._executor, given, self.workers))
        self._jobs = JobPool(self.factory, self._executor, self._slots, runner=self.runner_id,
                             should_stop=self._stop.is_set, max_trajectories=self.max_trajectories_per_job,
                             optimizers=self._optimizers, on_done=self._job_ended)
        if self._optimizers is not None:  # one a job, for as many jobs as the executor runs at once (at most 8)
            self._optimizers.start(processes=min(self.workers, OPTIMIZER_PROCESSES_AT_START))
        self._thread = threading.Thread(target=self._loop, name="driftlab-job-runner", daemon=True)
        self._thread.start()

    def wake(self) -> None:
        """Look for work of every kind now (a request queued some)."""
        with self._look_lock:
            self._look_everywhere = True
        self._wake.set()

    def _take_look_everywhere(self) -> bool:
        """Whether a look everywhere is due, and it is taken (a wake meanwhile is not lost: it sets it again)."""
        with self._look_lock:
            look, self._look_everywhere = self._look_everywhere, False
        return look

    def _job_ended(self, _job_id: int, status: str | None) -> None:
        """A job's share is free: the next claimable job may start (one the runner handed back is claimable again)."""
        if status == lifecycle.WorkStatus.QUEUED:
            self._jobs_left = True
        self._wake.set()

    def stop(self) -> None:
        """Stops taking work, lets each piece hand itself back for at most STOP_WAIT_S, hands back whatever this
        runner still holds (queued again, its stored results kept), then ends the workers."""
        self._stop_by = time.monotonic() + STOP_WAIT_S
        self._stop.set()
        self.wake()
        if self._thread is not None:
            self._thread.join(timeout=self._left())
        with storage.transaction(self.factory) as session:
            for table in (Job, Study, Rescore, Calibration):
                lease.hand_back(session, table, runner=self.runner_id)
        if self._executor is not None:
            self._executor.shutdown()
        if self._optimizers is not None:
            self._optimizers.shutdown()

    def _left(self) -> float | None:
        """What is left of the stop's wait (None: no stop asked, the loop ended otherwise)."""
        return None if self._stop_by == float("inf") else max(self._stop_by - time.monotonic(), 0.0)

    def _requeue_jobs_waiting_for_the_cluster(self) -> None:
        """Jobs paused because the cluster went away continue once the executor reaches it again."""
        if not getattr(self._executor, "connected", True):
            return
        with storage.transaction(self.factory) as session:
            for job in session.scalars(select(Job).where(Job.status == lifecycle.WorkStatus.PAUSED,
                                                         Job.error.startswith(EXECUTOR_LOST))):
                lifecycle.requeue(session, job_id=job.id)
            for study in session.scalars(select(Study).where(Study.status == lifecycle.WorkStatus.PAUSED,
                                                             Study.error.startswith(EXECUTOR_LOST))):
                studies.resume_study(session, study_id=study.id)

    def _claim_jobs(self, room: int) -> list[int]:
        """Claims up to ``room`` claimable jobs in one transaction: a seeds study's 8 jobs in 11.3 ms, against 21.8 ms
        in three transactions a job (medians of 7, a real SQLite file), all before its first episode."""
        running = set(self.running_job_ids)  # ours, a heartbeat late: their threads still run them
        claimed: list[int] = []
        with storage.transaction(self.factory) as session:
            for job_id in lifecycle.claimable(session, limit=room + len(running)):
                if len(claimed) == room:
                    break
                if job_id in running:
                    continue
                try:
                    lifecycle.claim(session, job_id=job_id, runner=self.runner_id)
                except lifecycle.TransitionError:  # another runner was quicker, or its lease is live
                    continue
                claimed.append(job_id)
        return claimed

    def _start_claimable_jobs(self, look_everywhere: bool) -> bool:
        """Claims what it can (no more jobs at once than the executor has workers) and starts them together; a job
        that stops wakes the loop: its share is free for the next. Between looks everywhere (``look_everywhere``
        False) it claims only while the last claim left jobs behind."""
        room = self._jobs.free
        if room <= 0 or not (self._jobs_left or look_everywhere):
            return False
        claimed = self._claim_jobs(room)
        self._jobs_left = len(claimed) == room
        self._jobs.start(claimed)
        return bool(claimed)

    def _start_side_tasks(self) -> None:
        """One robustness study, one rescore and one calibration at a time, each on its share of the slots beside
        the jobs (none waits for the queue): the same lease (driftlab.db.lease), the same run signature."""
        for kind, table, also, run in (("study", Study, Study.kind == StudyKind.ROBUSTNESS, run_study),
                                       ("rescore", Rescore, True, run_rescore),
                                       ("calibration", Calibration, True, run_stored_calibration)):
            self._start_side_task(kind, table, also, run)

    def _start_side_task(self, kind: str, table: Any, also: Any, run: Callable[..., str]) -> None:
        running = self._side_tasks.get(kind)
        if running is not None and running[1].is_alive():
            return
        with storage.transaction(self.factory) as session:
            row_id = lease.next_claimable(session, table, also)
            if row_id is None or not lease.claim(session, table, row_id=row_id, runner=self.runner_id, also=also):
                self._side_tasks.pop(kind, None)
                return

        def target() -> None:
            try:
                run(self.factory, row_id, self._executor, runner=self.runner_id, slots=self._slots,
                    owner=(kind, row_id), should_stop=self._stop.is_set)
            finally:
                self.wake()
        thread = threading.Thread(target=target, daemon=True, name=f"driftlab-{kind}-{row_id}")
        self._side_tasks[kind] = (row_id, thread)
        thread.start()

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                look_everywhere = self._take_look_everywhere()
                if look_everywhere:
                    self._requeue_jobs_waiting_for_the_cluster()
                    self._start_side_tasks()
                if self._start_claimable_jobs(look_everywhere):
                    continue
                if not self._wake.wait(self.busy_poll_s if self.running_job_ids else self.poll_s):
                    self.wake()  # work queued elsewhere (another server, the CLI, a dead runner)
                self._wake.clear()
        finally:  # each hands itself back at its next look at should_stop; stop() hands back what has not
            self._jobs.join(timeout_s=self._left())
            for _, thread in list(self._side_tasks.values()):
                thread.join(timeout=self._left())
