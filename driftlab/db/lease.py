"""The lease that lets exactly one runner run a piece of work at a time: a job, a robustness study, a rescore, a
calibration (any table with the columns ``id``, ``status``, ``runner_id``, ``heartbeat_at`` and ``error``).

The contract every kind keeps: a row is claimable when it is queued or its runner is dead (:func:`next_claimable`,
oldest first); :func:`claim` takes it (one conditional UPDATE); the runner renews it (:func:`renew`) at least every
HEARTBEAT_S and stops when a renewal fails (paused, cancelled, deleted or taken over); :func:`release` ends it with
the status the runner reached unless a request changed it meanwhile.

A runner takes the lease with one conditional UPDATE (two runners racing for it cannot both win), renews the
heartbeat while it runs, and clears the lease when it stops. A heartbeat older than ``LEASE_TIMEOUT_S`` belongs to
a dead runner (kill -9, power loss) and may be taken over.
"""

from __future__ import annotations

import os
import socket
import uuid
from datetime import datetime, timedelta
from typing import Any, cast

from sqlalchemy import CursorResult, Executable, or_, select, update
from sqlalchemy.orm import Session

from driftlab.db.models import WorkStatus, utcnow

LEASE_TIMEOUT_S = 15.0  # a runner renews every HEARTBEAT_S; three missed renewals and more mean it is gone
HEARTBEAT_S = 2.0
RUNNING = WorkStatus.RUNNING
ACTIVE = (WorkStatus.QUEUED, WorkStatus.RUNNING)


class TransitionError(RuntimeError):
    """The work is not in a status that allows this (HTTP 409, CLI exit 2)."""


def pause(row: Any, what: str) -> Any:
    """A queued or running row is paused (its runner sees it at its next heartbeat and stops)."""
    if row.status not in ACTIVE:
        raise TransitionError(f"{what} is {row.status}; pause needs queued or running")
    row.status = WorkStatus.PAUSED
    return row


def requeue(row: Any, what: str) -> Any:
    """A paused or failed row is queued again."""
    if row.status not in (WorkStatus.PAUSED, WorkStatus.FAILED):
        raise TransitionError(f"{what} is {row.status}; resume needs paused or failed")
    row.status, row.error = WorkStatus.QUEUED, None
    return row


def cancel(row: Any) -> Any:
    """A queued or running row is cancelled, its lease cleared (its runner sees it at its next heartbeat)."""
    row.status = WorkStatus.CANCELLED
    row.runner_id, row.heartbeat_at = None, None
    return row


def new_runner_id(kind: str) -> str:
    """A runner's identity: what it is, where, which process, and a nonce (pids are reused)."""
    return f"{kind}@{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def naive(moment: datetime) -> datetime:
    return moment.replace(tzinfo=None)  # SQLite stores naive datetimes; compare like with like


def stale_before(now: datetime) -> datetime:
    return naive(now - timedelta(seconds=LEASE_TIMEOUT_S))


def is_stale(table: Any, now: datetime):
    """SQL: the heartbeat is missing or older than the lease timeout (its runner is gone)."""
    return or_(table.heartbeat_at.is_(None), table.heartbeat_at < stale_before(now))


def is_live(row: Any, now: datetime | None = None) -> bool:
    """A runner holds ``row`` now."""
    now = now or utcnow()
    return (row.status == RUNNING and row.runner_id is not None and row.heartbeat_at is not None
            and naive(row.heartbeat_at) >= stale_before(now))


def rows_updated(session: Session, statement: Executable) -> int:
    """Rows an UPDATE matched (``Session.execute`` types its result as a plain Result; an UPDATE's is a cursor's)."""
    return cast(CursorResult[Any], session.execute(statement)).rowcount


def next_claimable(session: Session, table: Any, also: Any = True) -> int | None:
    """The oldest row of ``table`` that is queued, or whose runner died, where ``also`` (an SQL condition) holds."""
    stale = (table.status == RUNNING) & is_stale(table, utcnow())
    return session.scalar(select(table.id).where(or_(table.status == WorkStatus.QUEUED, stale), also)
                          .order_by(table.id).limit(1))


def claim(session: Session, table: Any, *, row_id: int, runner: str, also: Any = True) -> bool:
    """Take the lease of a queued row, or of one whose runner died (:func:`take` from queued, now)."""
    return take(session, table, row_id=row_id, runner=runner, from_statuses=(WorkStatus.QUEUED,), now=utcnow(),
                also=also)


def take(session: Session, table: Any, *, row_id: int, runner: str, from_statuses: tuple[str, ...], now: datetime,
         also: Any = True, **values: Any) -> bool:
    """Take the lease of ``table`` row ``row_id`` from one of ``from_statuses`` or from a dead runner, where ``also``
    (an SQL condition) holds, setting ``values`` too in the same UPDATE; False if the row is not claimable (or another
    runner was quicker)."""
    claimable = or_(table.status.in_([str(s) for s in from_statuses]),
                    (table.status == RUNNING) & is_stale(table, now)) & also
    return rows_updated(session, update(table).where(table.id == row_id, claimable)
                        .values(status=RUNNING, runner_id=runner, heartbeat_at=naive(now), error=None, **values)
                        .execution_options(synchronize_session=False)) == 1


def renew(session: Session, table: Any, *, row_id: int, runner: str, now: datetime | None = None) -> bool:
    """Renew the heartbeat; False when ``runner`` no longer holds the row (paused, deleted or taken over): stop."""
    return rows_updated(session, update(table).where(table.id == row_id, table.runner_id == runner,
                                                    table.status == RUNNING)
                        .values(heartbeat_at=naive(now or utcnow()))
                        .execution_options(synchronize_session=False)) == 1


def release(session: Session, table: Any, *, row_id: int, runner: str, status: str, error: str | None = None,
            **values: Any) -> None:
    """The runner stops: the row takes ``status`` unless someone changed it meanwhile (a pause request stays
    paused; a row taken over stays with its new runner), and the lease is cleared, with ``values`` set in the same
    UPDATE (only while ``runner`` still holds the row)."""
    session.execute(update(table).where(table.id == row_id, table.runner_id == runner, table.status == RUNNING)
                    .values(status=status, error=error).execution_options(synchronize_session=False))
    session.execute(update(table).where(table.id == row_id, table.runner_id == runner)
                    .values(runner_id=None, heartbeat_at=None, **values).execution_options(synchronize_session=False))


def hand_back(session: Session, table: Any, *, runner: str) -> int:
    """Every row of ``table`` that ``runner`` holds goes back to the queue, its lease cleared (a runner that stops
    before its threads have: the next runner takes the work up, an episode in flight is run again). Returns how many."""
    return rows_updated(session, update(table).where(table.runner_id == runner, table.status == RUNNING)
                        .values(status=WorkStatus.QUEUED, runner_id=None, heartbeat_at=None, error=None)
                        .execution_options(synchronize_session=False))
