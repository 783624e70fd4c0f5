"""Runs one stored rescore (driftlab.db.rescores): a job's best theta, exactly as stored, under fresh seeds (the
same episodes as ``driftlab rescore``), on the runner's executor and its share of the episode slots, like a job.

Each seed's result is committed as it comes back, so a rescore interrupted by a restart continues with the seeds
still missing; a cancelled one (``DELETE /api/jobs/{id}/rescore``) stops at the next heartbeat, its episodes in
flight dropped.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.robust import SampleResult, summarize
from driftlab.db import lease, rescores, storage
from driftlab.db.models import Rescore, WorkStatus
from driftlab.worker.executors import EpisodeExecutor, EpisodeOutcome
from driftlab.worker.slots import EpisodeSlots
from driftlab.worker.slotted import LeaseKept, SlottedEpisodes


def run_rescore(factory: sessionmaker[Session], rescore_id: int, executor: EpisodeExecutor, *, runner: str,
                slots: EpisodeSlots, owner: Hashable, should_stop: Callable[[], bool] = lambda: False) -> str:
    """Runs a rescore whose lease ``runner`` holds until every seed is back (finished), it is cancelled, or
    ``should_stop()`` (the runner shuts down: back to the queue, its samples kept). Returns its status."""
    with storage.snapshot(factory) as session:
        rescore = session.get(Rescore, rescore_id)
        theta, config, seeds = dict(rescore.theta), dict(rescore.config), list(rescore.seeds)
        back = {s["seed"] for s in rescore.samples}
    def renew() -> bool:
        with storage.transaction(factory) as session:
            return lease.renew(session, Rescore, row_id=rescore_id, runner=runner)
    lease_kept = LeaseKept(renew, should_stop)

    def store(_index: int, outcome: EpisodeOutcome) -> None:
        with storage.transaction(factory) as session:
            lease_kept.held = rescores.add_sample(session, rescore_id=rescore_id, runner=runner,
                                                  sample=outcome.sample.as_dict())
    try:
        with SlottedEpisodes(executor, slots, owner) as episodes:
            episodes.run([(theta, config, seed) for seed in seeds if seed not in back], store, lease_kept)
    except Exception as exc:  # a worker that died mid-episode: the rescore failed, its samples stay
        return _release(factory, rescore_id, runner, WorkStatus.FAILED, error=f"{type(exc).__name__}: {exc}")
    if should_stop():
        return _release(factory, rescore_id, runner, WorkStatus.QUEUED)
    if not lease_kept.held:  # cancelled, or taken over by another runner
        with storage.snapshot(factory) as session:
            rescore = session.get(Rescore, rescore_id)
            return rescore.status if rescore is not None else WorkStatus.CANCELLED
    return _finish(factory, rescore_id, runner)


def _finish(factory, rescore_id: int, runner: str) -> str:
    with storage.transaction(factory) as session:
        rescore = session.get(Rescore, rescore_id)
        order = {seed: i for i, seed in enumerate(rescore.seeds)}
        samples = sorted(rescore.samples, key=lambda s: order[s["seed"]])
        result = {**summarize([SampleResult.from_dict(s) for s in samples]), "seeds": [s["seed"] for s in samples]}
        rescores.finish(session, rescore_id=rescore_id, runner=runner, status=WorkStatus.FINISHED, result=result)
    return WorkStatus.FINISHED


def _release(factory, rescore_id: int, runner: str, status: WorkStatus, error: str | None = None) -> str:
    with storage.transaction(factory) as session:
        rescores.finish(session, rescore_id=rescore_id, runner=runner, status=status,
                        error=None if error is None else error[:2000])
    return status
