"""Runs one tuning job: rebuild the optimizer from stored evaluations, then ask, evaluate (one episode per
seed), store, tell.

Shared by `driftlab tune` and the server's worker. Every evaluation is committed as it completes; a job
that was interrupted continues from what is stored, with no repeated evaluation and unbroken numbering.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable
from concurrent.futures import CancelledError, Future
from dataclasses import dataclass, replace

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.config import Theta
from driftlab.core.convergence import best_so_far
from driftlab.core.drivability import check_drivable
from driftlab.core.errors import ConfigError
from driftlab.core.robust import RobustScore, SampleResult
from driftlab.core.statuses import EpisodeStatus
from driftlab.core.tuning import TuningSpec
from driftlab.db import enqueued, group_commit, lifecycle, storage
from driftlab.db.lifecycle import WorkStatus
from driftlab.db.models import Job
from driftlab.settings import MAX_TRAJECTORIES_PER_JOB
from driftlab.worker.executors import EpisodeExecutor, EpisodeOutcome
from driftlab.worker.optimizer_host import OptimizerHost, restore_optimizer
from driftlab.worker.seed_queue import PendingEvaluation, SeedQueue
from driftlab.worker.slots import EpisodeSlots


@dataclass
class Progress:
    n_done: int
    iterations: int
    best_J: float | None
    last: RobustScore | None
    seconds_per_evaluation: float | None

    @property
    def eta_s(self) -> float | None:
        if self.seconds_per_evaluation is None:
            return None
        return (self.iterations - self.n_done) * self.seconds_per_evaluation


EXECUTOR_LOST = "episode executor unreachable"


def is_executor_lost(exc: BaseException) -> bool:
    """A cluster that went away (connection closed or refused, timed out, futures cancelled by a lost client),
    as opposed to an episode that raised."""
    return isinstance(exc, (ConnectionError, TimeoutError, CancelledError)) or type(exc).__name__ in (
        "CommClosedError", "FutureCancelledError", "SchedulerUnreachable")


def interrupted_status(exc: BaseException) -> tuple[WorkStatus, str]:
    """What a run that raised ends as, and its error text: a lost cluster pauses it (resumed when the cluster is
    back), anything else fails it. Either way what is stored stays."""
    text = f"{type(exc).__name__}: {exc}"
    if is_executor_lost(exc):
        return WorkStatus.PAUSED, f"{EXECUTOR_LOST}: {text}"[:2000]
    return WorkStatus.FAILED, text[:2000]


def _next_evaluation(lease: _Lease, spec: TuningSpec, optimizer, in_flight: list[PendingEvaluation],
                     seeds: list[int]) -> PendingEvaluation:
    """The oldest theta enqueued for the job and not in flight (POST /api/jobs/{id}/enqueue; told to the optimizer
    like any other once evaluated), where the lease has seen any, else the optimizer's next proposal."""
    if lease.enqueued:
        taken = {e.enqueued_id for e in in_flight if e.enqueued_id is not None}
        with storage.snapshot(lease.factory) as session:
            row = next(iter(enqueued.waiting(session, job_id=lease.job_id, taken=taken, limit=1)), None)
            if row is not None:
                theta = Theta.filled(row.theta)
                return PendingEvaluation({k: float(theta[k]) for k in spec.bounds}, seeds, enqueued_id=row.id)
        lease.enqueued = False  # none left to take: the next heartbeat looks again
    return PendingEvaluation(optimizer.ask(), seeds)


STORED, OVER_BUDGET, LOST = "stored", "over_budget", "lost"


def _store(factory: sessionmaker[Session], lease: _Lease, evaluation: PendingEvaluation,
           scored: tuple[RobustScore, list[SampleResult], EpisodeOutcome]) -> str:
    """Commit the evaluation if this runner still holds the job (LOST if the job was taken over or deleted: its
    new runner asks again, and no index is stored twice) and the budget has room (OVER_BUDGET: a PATCH lowered it
    while the evaluation ran; nothing is stored past ``iterations``). Reads the job's status and budget in the same
    write transaction, so a pause or a new budget takes effect at the next evaluation, not the next heartbeat."""
    score, samples, shown = scored
    metrics = {**shown.metrics, "n_samples": len(samples), "n_completed": score.n_completed,
               "J_samples_mean": score.J}
    if evaluation.pruned:  # only then: an evaluation that ran every seed keeps the metrics it always had
        metrics["pruned"] = True

    def store(session: Session) -> str:
        job = storage.job_for_store(session, job_id=lease.job_id)
        if job is None or job.runner_id != lease.runner:
            return LOST
        lease.observe(job)
        if job.n_evaluations >= lease.iterations:
            return OVER_BUDGET
        storage.add_evaluation(session, job_id=lease.job_id, index=job.n_evaluations, theta=evaluation.theta,
                               J=score.J, status=score.status,
                               metrics=metrics, trigger_points=shown.trigger_points,
                               wall_ms=sum(o.wall_ms for o in evaluation.outcomes.values()),
                               columns=shown.columns, trajectory=shown.packed,  # packed by its worker
                               seeds=[s.as_dict() for s in samples], trajectory_seed=shown.seed,
                               max_trajectories=lease.max_trajectories,
                               enqueued=evaluation.enqueued_id is not None)
        if evaluation.enqueued_id is not None:  # stored and taken off the queue in one commit
            enqueued.remove(session, row_id=evaluation.enqueued_id)
        return STORED

    return group_commit.write(factory, store)  # committed with the other jobs' evaluations waiting then


def claim_job(factory: sessionmaker[Session], job_id: int, runner: str,
              from_statuses: tuple[WorkStatus, ...] = (WorkStatus.QUEUED,)) -> None:
    """Take the job's lease (raises LeaseHeld or TransitionError, see driftlab.db.lifecycle)."""
    with storage.transaction(factory) as session:
        lifecycle.claim(session, job_id=job_id, runner=runner, from_statuses=from_statuses)


class _Lease:
    """Renews the job's lease every HEARTBEAT_S; tells when it is lost, what the budget is now, and whether thetas
    are enqueued for the job (``enqueued``: looked for in the run's first read and at each heartbeat, not at every
    ask, which would add a read to every evaluation)."""

    def __init__(self, factory: sessionmaker[Session], job_id: int, runner: str, iterations: int,
                 max_trajectories: int, enqueued: bool) -> None:
        """``enqueued``: whether thetas waited for the job when the run read it first."""
        self.factory, self.job_id, self.runner = factory, job_id, runner
        self.iterations = iterations
        self.max_trajectories = max_trajectories
        self.held = True
        self.enqueued = enqueued
        self._last = time.monotonic()

    def observe(self, job: storage.JobForStore | None) -> None:
        """What the stored job says now: gone, taken over or paused (by a request) means stop; the budget may have
        changed."""
        if job is None or job.runner_id != self.runner:
            self.held = False
            return
        self.iterations = job.iterations
        if job.status != WorkStatus.RUNNING:
            self.held = False

    def look_again(self) -> None:
        """What the stored job says now, read without renewing (the run is about to end, and its release writes)."""
        if self.held:
            with storage.snapshot(self.factory) as session:
                self.observe(storage.job_for_store(session, job_id=self.job_id))

    def renew_if_due(self) -> None:
        if not self.held or time.monotonic() - self._last < lifecycle.HEARTBEAT_S:
            return
        with storage.transaction(self.factory) as session:
            self.held = lifecycle.heartbeat(session, job_id=self.job_id, runner=self.runner)
            self.observe(storage.job_for_store(session, job_id=self.job_id))  # its status and budget, not the row
            self.enqueued = enqueued.any_waiting(session, job_id=self.job_id)
        self._last = time.monotonic()


def _fitted_spec(factory: sessionmaker[Session], job_id: int, document: dict, first_run: bool) -> TuningSpec:
    """The job's ``document``, parsed once for this run. A job queued with its config still to be fitted to its plant
    (parsing does no physics: POST /api/jobs and `driftlab tune` store it so) is fitted once, here, off the server's
    request path, and stored fitted: what every episode of it runs, and what re-runs it, is the stored config
    (driftlab.core.configure.fitted)."""
    spec = TuningSpec.from_dict(document)
    if first_run:  # a job posted while the server compiled its check was stored unchecked (server/drift_check.py)
        check_drivable(spec.config)
    if not spec.config.to_fit:
        return spec
    spec = spec.fitted()
    fitted_document = spec.to_dict()
    with storage.transaction(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        # the config and the document's version and "fitted"; a budget raised meanwhile stays
        job.spec = {**job.spec, **{k: fitted_document[k] for k in ("version", "fitted", "config")}}
        return replace(spec, iterations=int(job.spec["iterations"]))


def _may_ask(startable: bool) -> bool:
    """Whether to ask the next theta now: while no episode waits that a freed worker could start (a seed held back
    by :meth:`SeedQueue.any_startable`'s rules does not count), so a worker that frees up starts one at once instead of
    idling through the ask (the job default's 500-run: 0.92x the wall time of asking up to three ahead). The optimizer
    knows no less: an evaluation is told once all its seeds are in, so the unfinished ones are pending either way; at
    most one more is pending than there are workers."""
    return not startable


def run_job(factory: sessionmaker[Session], job_id: int, executor: EpisodeExecutor, *, runner: str,
            workers: int = 1, slots: EpisodeSlots | None = None, owner: Hashable | None = None,
            should_stop: Callable[[], bool] = lambda: False,
            on_progress: Callable[[Progress], None] | None = None, optimizers: OptimizerHost | None = None,
            max_trajectories: int = MAX_TRAJECTORIES_PER_JOB) -> str:
    """Runs a job whose lease ``runner`` holds (:func:`claim_job`) until its budget is spent, it is paused
    (the lease is lost), or ``should_stop()`` (the runner shuts down: the job goes back to the queue). Returns
    the status it leaves the job in and releases the lease.

    Each evaluation runs one episode per seed of the job (``robust_samples`` of them, the same seeds for every
    theta) on the executor; one that completes every episode with a J better than the best so far then runs
    ``confirm_samples`` more seeds, and is stored with all of them. Once a seed fails, the seeds of that evaluation
    not started yet are skipped (:meth:`SeedQueue.skip_unstarted`; not in a deterministic job); once its first seeds are
    worse than the best evaluation's on the same seeds with confidence, it stops there (the job's ``prune`` rule,
    :meth:`SeedQueue.prune_if_worse`, stored with ``metrics["pruned"]``). The job keeps at most its
    share of ``slots`` episodes in flight (the executor's capacity shared with the other jobs running on it, see
    driftlab.worker.slots; ``workers`` alone when no ``slots`` are given; ``owner`` names the job there, if the
    caller joined it already); an evaluation's episodes wait for a slot, and a new theta is asked whenever no episode
    waits that may start (:func:`_may_ask`), so with several samples per evaluation the optimizer stays nearly
    sequential (one evaluation more in flight than the workers). With ``optimizers`` the job's optimizer runs in that
    host process (driftlab.worker.optimizer_host: the server's), else on this thread. The job keeps the trajectories
    of its first ``max_trajectories`` evaluations and of every new best (Settings.max_trajectories_per_job).
    """
    slots = slots or EpisodeSlots(workers)
    owner, wake = owner if owner is not None else object(), threading.Event()
    slots.join(owner, wake)
    try:
        return _run(factory, job_id, executor, runner, slots, owner, wake, should_stop, on_progress, optimizers,
                    max_trajectories)
    finally:
        slots.leave(owner)


def _run(factory: sessionmaker[Session], job_id: int, executor: EpisodeExecutor, runner: str, slots: EpisodeSlots,
         owner: object, wake: threading.Event, should_stop: Callable[[], bool],
         on_progress: Callable[[Progress], None] | None, optimizers: OptimizerHost | None,
         max_trajectories: int) -> str:
    # One read of what the run starts from (this runner holds the lease: nobody else appends to the job meanwhile).
    with storage.snapshot(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        document = job.spec
        stored = storage.evaluations(session, job_id=job_id)
        history = [(e.theta, e.J if e.completed else None, e.J) for e in stored]
        curve = best_so_far([e.J for e in stored], [e.completed for e in stored])  # what the stop rules read
        best = curve[-1] if stored else None
        # The best's J on each of its seeds, what the prune rule pairs a candidate's seeds with: the lowest completed
        # J, the earliest on a tie (as `best` and storage.best_evaluation pick it).
        leader = min((e for e in stored if e.completed), key=lambda e: (e.J, e.index), default=None)
        incumbent_J = None if leader is None else {int(s["seed"]): float(s["J"]) for s in leader.seeds or []}
        ran_before_s = job.run_s or 0.0
        any_enqueued = enqueued.any_waiting(session, job_id=job_id)
    try:
        spec = _fitted_spec(factory, job_id, document, first_run=not stored)
    except ConfigError as exc:  # the car cannot be fitted at this drift after all: the job fails, saying why
        status, error = interrupted_status(exc)
        with storage.transaction(factory) as session:
            lifecycle.release(session, job_id=job_id, runner=runner, status=status, error=error)
        return status
    optimizer = optimizers.open(spec, history) if optimizers is not None else restore_optimizer(spec, history)
    config_doc = spec.to_dict()["config"]
    seeds, confirm_seeds = spec.episode_seeds, spec.confirm_seeds
    lease = _Lease(factory, job_id, runner, spec.iterations, max_trajectories, any_enqueued)
    n_done = len(history)
    evaluations: list[PendingEvaluation] = []
    episodes: dict[Future[EpisodeOutcome], PendingEvaluation] = {}
    waiting = SeedQueue(spec.prune, best, incumbent_J, spec.deterministic)  # asked episodes waiting for a slot

    def submit_waiting() -> None:
        while waiting.any_startable() and slots.try_take(owner):
            evaluation, seed = waiting.pop_startable()
            future = executor.submit(evaluation.theta, config_doc, seed)
            future.add_done_callback(lambda _: wake.set())
            episodes[future] = evaluation

    started = time.perf_counter()
    n_at_start = n_done
    shutting_down = False
    stop_reason = None
    try:
        while True:
            # A stop rule (driftlab.core.stopping) asks nothing more; what was asked completes and is stored. The
            # no-improvement window counts this run's evaluations (from the best before it): a job resumed or given
            # a larger budget runs at least that many more; and only those after the space-filling design (its
            # warm-up, as Optuna's and W&B's early stops have one): the design explores, it is not meant to improve.
            if spec.stop.any and stop_reason is None:
                stop_reason = spec.stop.reason(ran_before_s + time.perf_counter() - started,
                                               curve[max(n_at_start - 1, spec.seed_points - 1, 0):])
            if n_done >= lease.iterations and not episodes and not waiting:
                lease.look_again()  # a budget raised at the last moment still counts
                if n_done >= lease.iterations or not lease.held:
                    break
            lease.renew_if_due()
            shutting_down = shutting_down or should_stop()
            if shutting_down:  # the runner stops (SIGTERM; Docker kills 10 s later), not the job: what is unfinished
                break          # is dropped and the next runner asks again (a pause, below, completes what it asked)
            stopping = not lease.held or stop_reason is not None
            # Deterministic: one evaluation at a time (its seeds still run in parallel), so the optimizer's
            # history never depends on which worker finished first.
            free = not evaluations if spec.deterministic else _may_ask(waiting.any_startable())
            while (not stopping and free and n_done + len(evaluations) < lease.iterations):
                evaluation = _next_evaluation(lease, spec, optimizer, evaluations, seeds)
                evaluations.append(evaluation)
                waiting.add(evaluation, seeds)
                submit_waiting()
                free = not spec.deterministic and _may_ask(waiting.any_startable())
            submit_waiting()  # what is asked completes, paused or not: its episodes were started or are due
            if not episodes and not waiting and (stopping or n_done + len(evaluations) >= lease.iterations):
                break
            # Else wait for an episode to come back, or for a slot the other jobs free (the share may be full).
            wake.wait(timeout=lifecycle.HEARTBEAT_S)
            wake.clear()
            for future in [f for f in episodes if f.done()]:
                evaluation = episodes.pop(future)
                slots.give_back(owner)
                outcome = future.result()
                evaluation.outcomes[outcome.seed] = outcome
                if not outcome.completed and not spec.deterministic:
                    waiting.skip_unstarted(evaluation)
                else:  # decided before the freed workers take its next seeds (a stored one returns at once)
                    waiting.prune_if_worse(evaluation)
            submit_waiting()  # the freed workers take what waits before this thread stores, tells and asks
            for evaluation in [e for e in evaluations if e.done]:
                scored = evaluation.score()
                score = scored[0]
                if (confirm_seeds and not evaluation.confirming and not evaluation.pruned
                        and score.status == EpisodeStatus.COMPLETED and (best is None or score.J < best)):
                    # A would-be best must hold on more seeds before it counts (the winner's curse: among
                    # hundreds of thetas, some pass a few seeds by luck near a failure boundary).
                    evaluation.confirming = True
                    evaluation.seeds = evaluation.seeds + confirm_seeds
                    waiting.add(evaluation, confirm_seeds)
                    continue
                evaluations.remove(evaluation)
                outcome_of_store = _store(factory, lease, evaluation, scored)
                if outcome_of_store == LOST:
                    lease.held = False  # taken over: stop at once, the new runner owns the job
                    waiting.clear()
                    continue
                if outcome_of_store == OVER_BUDGET:
                    n_done = max(n_done, lease.iterations)  # the budget is spent: what is in flight is dropped
                    waiting.clear()
                    continue
                completed = score.status == EpisodeStatus.COMPLETED
                optimizer.tell(evaluation.theta, score.J if completed else None, score.J)
                n_done += 1
                if completed and not evaluation.pruned and (best is None or score.J < best):
                    best = score.J
                    waiting.new_best(best, {s.seed: s.J for s in scored[1]})
                curve.append(best)
                if on_progress is not None:
                    rate = (time.perf_counter() - started) / max(n_done - n_at_start, 1)
                    on_progress(Progress(n_done, lease.iterations, best, score, rate))
    except Exception as exc:
        status, error = interrupted_status(exc)
        with storage.transaction(factory) as session:
            lifecycle.release(session, job_id=job_id, runner=runner, status=status, error=error)
        return status
    finally:
        for future in episodes:
            future.cancel()
        if optimizers is not None:
            optimizer.close()
    if n_done >= lease.iterations or (stop_reason is not None and lease.held):
        status = WorkStatus.FINISHED
    elif shutting_down:
        status = WorkStatus.QUEUED  # the runner stops, not the job: the next runner continues it
    else:
        status = WorkStatus.PAUSED
    with storage.transaction(factory) as session:
        lifecycle.release(session, job_id=job_id, runner=runner, status=status,
                          stop_reason=stop_reason if n_done < lease.iterations else None)
        stored = session.scalar(select(Job.status).where(Job.id == job_id))
        return WorkStatus(stored) if stored is not None else status
