"""Runs one stored rescore (driftlab.db.rescores): a job's best theta, exactly as stored, under fresh seeds (the
same episodes as ``driftlab rescore``), on the runner's executor and its share of the episode slots, like a job.

Each seed's result is committed as it comes back, so a rescore interrupted by a restart continues with the seeds
still missing; a cancelled one (``DELETE /api/jobs/{id}/rescore``) stops at the next heartbeat, its episodes in
flight dropped.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable
from concurrent.futures import Future

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.robust import SampleResult, summarize
from driftlab.db import lease, rescores, storage
from driftlab.db.models import Rescore, RescoreStatus
from driftlab.worker.executors import EpisodeExecutor, EpisodeOutcome
from driftlab.worker.slots import EpisodeSlots


def run_rescore(factory: sessionmaker[Session], rescore_id: int, executor: EpisodeExecutor, *, runner: str,
                slots: EpisodeSlots, owner: Hashable, should_stop: Callable[[], bool] = lambda: False) -> str:
    """Runs a rescore whose lease ``runner`` holds until every seed is back (finished), it is cancelled, or
    ``should_stop()`` (the runner shuts down: back to the queue, its samples kept). Returns its status."""
    wake = threading.Event()
    slots.join(owner, wake)
    try:
        return _run(factory, rescore_id, executor, runner, slots, owner, wake, should_stop)
    finally:
        slots.leave(owner)


def _run(factory, rescore_id, executor, runner, slots, owner, wake, should_stop) -> str:
    with storage.snapshot(factory) as session:
        rescore = session.get(Rescore, rescore_id)
        theta, config, seeds = dict(rescore.theta), dict(rescore.config), list(rescore.seeds)
        back = {s["seed"] for s in rescore.samples}
    waiting = [seed for seed in seeds if seed not in back]
    in_flight: dict[Future[EpisodeOutcome], int] = {}
    held, last_beat = True, time.monotonic()
    try:
        while held and (waiting or in_flight):
            if should_stop():
                return _release(factory, rescore_id, runner, RescoreStatus.QUEUED)
            while waiting and slots.try_take(owner):
                future = executor.submit(theta, config, waiting.pop(0))
                future.add_done_callback(lambda _: wake.set())
                in_flight[future] = 0
            wake.wait(timeout=lease.HEARTBEAT_S)
            wake.clear()
            for future in [f for f in in_flight if f.done()]:
                del in_flight[future]
                slots.give_back(owner)
                sample = future.result().sample().as_dict()
                with storage.transaction(factory) as session:
                    held = rescores.add_sample(session, rescore_id=rescore_id, runner=runner, sample=sample)
            if time.monotonic() - last_beat >= lease.HEARTBEAT_S:
                with storage.transaction(factory) as session:
                    held = held and lease.renew(session, Rescore, row_id=rescore_id, runner=runner)
                last_beat = time.monotonic()
    except Exception as exc:  # a worker that died mid-episode: the rescore failed, its samples stay
        return _release(factory, rescore_id, runner, RescoreStatus.FAILED, error=f"{type(exc).__name__}: {exc}")
    for future in in_flight:
        future.cancel()
    if not held:  # cancelled, or taken over by another runner
        with storage.snapshot(factory) as session:
            rescore = session.get(Rescore, rescore_id)
            return rescore.status if rescore is not None else RescoreStatus.CANCELLED
    return _finish(factory, rescore_id, runner)


def _finish(factory, rescore_id: int, runner: str) -> str:
    with storage.transaction(factory) as session:
        rescore = session.get(Rescore, rescore_id)
        order = {seed: i for i, seed in enumerate(rescore.seeds)}
        samples = sorted(rescore.samples, key=lambda s: order[s["seed"]])
        result = {**summarize([SampleResult.from_dict(s) for s in samples]), "seeds": [s["seed"] for s in samples]}
        rescores.finish(session, rescore_id=rescore_id, runner=runner, status=RescoreStatus.FINISHED, result=result)
    return RescoreStatus.FINISHED


def _release(factory, rescore_id: int, runner: str, status: RescoreStatus, error: str | None = None) -> str:
    with storage.transaction(factory) as session:
        rescores.finish(session, rescore_id=rescore_id, runner=runner, status=status,
                        error=None if error is None else error[:2000])
    return status
