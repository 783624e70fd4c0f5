"""Runs one stored calibration (driftlab.db.calibrations; driftlab.services.calibration, the run ``driftlab
calibrate`` makes) on the runner's executor and its share of the episode slots, like a job. Its progress, messages
and profiles are stored as they come; a cancelled calibration (``DELETE /api/calibrations/{id}``) stops at its next
event, its episodes in flight dropped, the profiles it stored kept."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.calibration_request import CalibrationRequest
from driftlab.core.calibration_run import CalibrationStopped
from driftlab.core.errors import ConfigError
from driftlab.db import calibrations, lease, storage
from driftlab.db.models import Calibration, WorkStatus
from driftlab.services.calibration import run_calibration
from driftlab.worker.executors import EpisodeExecutor, EpisodeOutcome
from driftlab.worker.slots import EpisodeSlots
from driftlab.worker.slotted import SlottedEpisodes


def run_stored_calibration(factory: sessionmaker[Session], calibration_id: int, executor: EpisodeExecutor, *,
                           runner: str, slots: EpisodeSlots, owner: Hashable,
                           should_stop: Callable[[], bool] = lambda: False) -> str:
    """Runs a calibration whose lease ``runner`` holds until it is done, cancelled, or ``should_stop()`` (the
    runner shuts down: back to the queue). Returns its status."""
    with storage.snapshot(factory) as session:
        request = CalibrationRequest(**session.get(Calibration, calibration_id).request)
    reporter = _Reporter(factory, calibration_id, runner, should_stop)
    try:
        with SlottedEpisodes(executor, slots, owner) as episodes:
            run_calibration(request, factory, _slotted_batches(episodes, reporter.check), on_event=reporter)
        reporter.flush()
    except CalibrationStopped:
        return _release(factory, calibration_id, runner, WorkStatus.QUEUED if should_stop() else None)
    except ConfigError as exc:
        return _release(factory, calibration_id, runner, WorkStatus.FAILED, str(exc))
    except Exception as exc:  # a worker that died mid-episode: the calibration failed, its profiles stay
        return _release(factory, calibration_id, runner, WorkStatus.FAILED, f"{type(exc).__name__}: {exc}")
    return _release(factory, calibration_id, runner, WorkStatus.FINISHED)


class _Reporter:
    """Stores the run's events as they come (one per weight set or theta tried: a cancel stops the run at the end
    of the set in flight), renewing the lease; raises CalibrationStopped once the runner lost it (cancelled). Called
    from each thread of the candidate searches that run side by side: one at a time."""

    def __init__(self, factory, calibration_id: int, runner: str, should_stop: Callable[[], bool]) -> None:
        self.factory, self.calibration_id, self.runner, self.should_stop = factory, calibration_id, runner, should_stop
        self.progress: dict[str, Any] | None = None
        self.messages: list[str] = []
        self.last = 0.0
        self.lock = threading.RLock()

    def __call__(self, event: dict[str, Any]) -> None:
        with self.lock:
            if "message" in event:
                self.messages.append(event["message"])
            if "progress" in event:
                self.progress = event["progress"]
            self.flush(profile_id=event["profile"]["profile_id"] if "profile" in event else None)

    def flush(self, profile_id: int | None = None) -> None:
        with self.lock:
            with storage.transaction(self.factory) as session:
                held = calibrations.record(session, calibration_id=self.calibration_id, runner=self.runner,
                                           progress=self.progress, messages=self.messages, profile_id=profile_id)
            self.messages, self.last = [], time.monotonic()
        if not held:
            raise CalibrationStopped

    def check(self) -> None:
        """Between episodes: stop when asked, renewing the lease while a batch waits."""
        if self.should_stop():
            raise CalibrationStopped
        if time.monotonic() - self.last >= lease.HEARTBEAT_S:
            self.flush()


def calibration_score(outcome: EpisodeOutcome) -> tuple[str, float, float, float | None]:
    """An episode as a calibration scores it (driftlab.core.calibration.RunBatch): status, J, completed fraction,
    mean |e| [m]."""
    error = outcome.metrics.get("mean_abs_e_m")
    return (outcome.status, float(outcome.J), float(outcome.metrics.get("completed_fraction", 0.0)),
            None if error is None else float(error))


def _slotted_batches(episodes: SlottedEpisodes, check: Callable[[], None]):
    """A calibration's batches on the shared executor, never more in flight than its share of the slots."""
    def run(batch):
        results: list[Any] = [None] * len(batch)

        def scored(index: int, outcome: EpisodeOutcome) -> None:
            results[index] = calibration_score(outcome)

        def go_on() -> bool:
            check()  # raises CalibrationStopped: what is in flight is dropped
            return True
        episodes.run(batch, scored, go_on)
        return results
    return run


def _release(factory, calibration_id: int, runner: str, status: WorkStatus | None,
             error: str | None = None) -> str:
    """Ends the run: ``status`` unless it was cancelled (None: whatever it is now)."""
    with storage.transaction(factory) as session:
        if status is not None:
            calibrations.finish(session, calibration_id=calibration_id, runner=runner, status=status,
                                error=None if error is None else error[:2000])
        return session.get(Calibration, calibration_id).status
