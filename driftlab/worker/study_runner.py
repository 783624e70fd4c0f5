"""Runs a robustness study: its theta on every pending cell of the grid, one episode per seed on the executor
(the local pool or Dask, as a job's episodes) within its share of the episode slots (driftlab.worker.slotted), each
cell stored as soon as its episodes are back; a cell whose plant cannot drift the scenario is stored as not drivable
without running.

The runner holds the study's lease (driftlab.db.studies) as a job's runner holds the job's: a pause request,
a delete or a takeover ends the lease, and the runner stops after the episodes in flight. A study that was
interrupted continues with the cells still pending.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.drivability import drivable_reason
from driftlab.core.robust import aggregate
from driftlab.core.study import RobustnessStudySpec
from driftlab.db import storage, studies
from driftlab.db.lifecycle import WorkStatus
from driftlab.db.models import Study
from driftlab.worker.executors import EpisodeExecutor, EpisodeOutcome
from driftlab.worker.job_loop import interrupted_status
from driftlab.worker.slots import EpisodeSlots
from driftlab.worker.slotted import LeaseKept, SlottedEpisodes


@dataclass
class _PendingCell:
    cell_id: int
    config_doc: dict[str, Any]
    seeds: list[int]
    outcomes: dict[int, EpisodeOutcome] = field(default_factory=dict)

    @property
    def done(self) -> bool:
        return len(self.outcomes) == len(self.seeds)


def _store_cell(factory: sessionmaker[Session], study_id: int, runner: str, cell: _PendingCell) -> bool:
    """Commits the cell if this runner still holds the study (False: stop)."""
    samples = [cell.outcomes[s].sample for s in cell.seeds]
    score = aggregate(samples)
    with storage.transaction(factory) as session:
        if not studies.heartbeat_study(session, study_id=study_id, runner=runner):
            return False
        studies.store_cell(session, cell_id=cell.cell_id, status=score.status, J=score.J,
                           n_completed=score.n_completed, seeds=[s.as_dict() for s in samples],
                           wall_ms=sum(o.wall_ms for o in cell.outcomes.values()))
    return True


def _store_not_drivable(factory: sessionmaker[Session], study_id: int, runner: str, cell_ids: list[int]) -> None:
    """Cells whose plant has no drift at the scenario's radius and sideslip: stored as such, never run (an
    episode there says nothing about the controller, driftlab.core.drivability)."""
    if not cell_ids:
        return
    with storage.transaction(factory) as session:
        if not studies.heartbeat_study(session, study_id=study_id, runner=runner):
            return
        for cell_id in cell_ids:
            studies.store_cell(session, cell_id=cell_id, status=studies.NOT_DRIVABLE, J=None, n_completed=0,
                               seeds=[], wall_ms=0.0)


def run_study(factory: sessionmaker[Session], study_id: int, executor: EpisodeExecutor, *, runner: str,
              slots: EpisodeSlots, owner: Hashable = "study", should_stop: Callable[[], bool] = lambda: False) -> str:
    """Runs a study whose lease ``runner`` holds (:func:`driftlab.db.studies.claim_study`) on ``owner``'s share of
    the episode slots until every cell is stored, it is paused, or ``should_stop()`` (back to the queue; the cells
    not stored yet run again). Returns the status it leaves it in."""
    with storage.transaction(factory) as session:
        study = studies.get_study(session, study_id=study_id)
        spec = RobustnessStudySpec.from_dict(study.spec)
        todo = [(c.id, c.settings) for c in studies.cells(session, study_id=study_id) if c.status == studies.PENDING]
    seeds = spec.episode_seeds
    queue = [_PendingCell(cell_id, spec.cell_config(settings), seeds) for cell_id, settings in todo
             if drivable_reason(spec.cell_episode_config(settings)) is None]
    _store_not_drivable(factory, study_id, runner, [cell_id for cell_id, _ in todo
                                                    if cell_id not in {c.cell_id for c in queue}])
    tasks = [(cell, seed) for cell in queue for seed in seeds]
    def renew() -> bool:
        with storage.transaction(factory) as session:
            return studies.heartbeat_study(session, study_id=study_id, runner=runner)
    lease_kept = LeaseKept(renew, should_stop)

    def store(index: int, outcome: EpisodeOutcome) -> None:
        cell = tasks[index][0]
        cell.outcomes[outcome.seed] = outcome
        if cell.done and lease_kept.held:
            lease_kept.held = _store_cell(factory, study_id, runner, cell)
    try:
        with SlottedEpisodes(executor, slots, owner) as episodes:
            done = episodes.run([(spec.theta, cell.config_doc, seed) for cell, seed in tasks], store, lease_kept)
    except Exception as exc:
        status, error = interrupted_status(exc)
        with storage.transaction(factory) as session:
            studies.release_study(session, study_id=study_id, runner=runner, status=status, error=error)
        return status
    status = (WorkStatus.FINISHED if done and lease_kept.held else WorkStatus.QUEUED if should_stop()
              else WorkStatus.PAUSED)
    with storage.transaction(factory) as session:
        studies.release_study(session, study_id=study_id, runner=runner, status=status)
        study = session.get(Study, study_id)
        return study.status if study is not None else status
