"""Storage functions (keyword-only, no HTTP): jobs, evaluations, trajectories.

SQLite by default (where: :func:`driftlab.settings.database_url`), opened in WAL mode with a busy timeout so
readers never see "database is locked" while a worker commits; PostgreSQL (``postgresql+psycopg://...``) for
several app servers on one database.

Transactions: :func:`transaction` takes the database's write lock when it begins (SQLite's ``BEGIN IMMEDIATE``;
on PostgreSQL a transaction-scoped advisory lock, the same one for every writer, in READ COMMITTED: each statement
after it sees what every earlier writer committed), so a check and the write it guards see the same database (a
budget lowered by the API while a runner stores an evaluation: one of the two waits for the other, neither acts on
a count the other has already changed). :func:`snapshot` is for reads only: a consistent view (PostgreSQL:
REPEATABLE READ) that never blocks a writer. pysqlite's own transaction handling (BEGIN only before the first
write, reads outside any transaction) is switched off for this, as SQLAlchemy's SQLite docs describe.
"""

from __future__ import annotations

import json
import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from datetime import datetime
from typing import Any, cast

import numpy as np
from sqlalchemy import Connection, Engine, Table, bindparam, create_engine, event, func, insert, select
from sqlalchemy.orm import Session, sessionmaker

from driftlab.core.statuses import EpisodeStatus
from driftlab.db import schema
from driftlab.db.models import Evaluation, Job, Trajectory, WorkStatus
from driftlab.db.trajectory_bytes import PackedTrajectory, unpack

_BUSY_TIMEOUT_MS = 30_000
_BEGIN_OPTION = "driftlab_sqlite_begin"
_WRITE_LOCK_KEY = 0x6472696674  # PostgreSQL's advisory lock every DriftLab write transaction takes ("drift")
_POOLED_CONNECTIONS = 20


class NotFound(LookupError):
    """No such job or evaluation."""


def open_database(url: str) -> sessionmaker[Session]:
    """Engine and session factory; creates or upgrades the schema to the newest revision."""
    sqlite = url.startswith("sqlite")
    # A connection per request thread kept open (FastAPI's thread pool runs up to 40 at once): with SQLAlchemy's
    # default pool of 5, every request past the fifth opened a connection and ran its pragmas, then closed it.
    # A PostgreSQL server shares its connections (100 by default) among every app server: fewer each, and a request
    # past them waits for one (pool_timeout) instead of being refused.
    pool = ({"pool_size": _POOLED_CONNECTIONS, "max_overflow": 2 * _POOLED_CONNECTIONS, "pool_use_lifo": True}
            if _is_sqlite_file(url) else {} if sqlite else
            {"pool_size": _POOLED_CONNECTIONS // 2, "max_overflow": _POOLED_CONNECTIONS // 2, "pool_use_lifo": True})
    engine = create_engine(url, connect_args={"timeout": _BUSY_TIMEOUT_MS / 1000} if sqlite else {},
                           json_serializer=finite_json, **pool)
    if sqlite:
        event.listen(engine, "connect", _sqlite_pragmas)
        event.listen(engine, "begin", _sqlite_begin)
    elif engine.dialect.name == "postgresql":
        event.listen(engine, "begin", _postgresql_begin)
    schema.upgrade(engine)
    return sessionmaker(engine, expire_on_commit=False)


def finite_json(value: Any) -> str:
    """A JSON column's text, as the standard has it: a NaN or an infinity (a metric of an episode that never took
    a step) is stored as null. PostgreSQL refuses them, and the API could not send them."""
    try:
        return json.dumps(value, allow_nan=False)
    except ValueError:
        return json.dumps(_finite(value), allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def _is_sqlite_file(url: str) -> bool:
    return url.startswith("sqlite") and url.split("///", 1)[-1] not in ("", ":memory:") and "mode=memory" not in url


def close_database(factory: sessionmaker[Session]) -> None:
    """A clean stop: SQLite's write-ahead log copied into the database file and every connection closed (the last
    close removes the -wal file), so that the database file alone, copied after the stop, holds every evaluation."""
    engine = engine_of(factory)
    if engine.dialect.name == "sqlite":
        with engine.connect() as connection:
            connection.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
    engine.dispose()


def _sqlite_pragmas(dbapi_connection, _record) -> None:
    dbapi_connection.isolation_level = None  # SQLAlchemy emits BEGIN itself: _sqlite_begin
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute(f"PRAGMA busy_timeout={_BUSY_TIMEOUT_MS}")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()


def _sqlite_begin(connection) -> None:
    mode = connection.get_execution_options().get(_BEGIN_OPTION, "DEFERRED")
    connection.exec_driver_sql(f"BEGIN {mode}")


def _postgresql_begin(connection) -> None:
    if connection.get_execution_options().get(_BEGIN_OPTION) == "IMMEDIATE":
        connection.exec_driver_sql(f"SELECT pg_advisory_xact_lock({_WRITE_LOCK_KEY})")


def engine_of(factory: sessionmaker[Session]) -> Engine:
    return factory.kw["bind"]


# SQLite's writers of one process queue on a lock of the process first: a writer that finds SQLite's lock taken
# polls it with growing sleeps (up to 100 ms), so under eight job threads a store waited ~45 ms for a lock free
# most of the time. Another process's writers still meet SQLite's own lock. Keyed by the database's URL, so two
# engines on one file share it; reentrant, so a transaction opened inside another on the same thread fails on
# SQLite's busy timeout as before instead of blocking forever.
_WRITERS: dict[str, threading.RLock] = {}
_WRITERS_LOCK = threading.Lock()


def _writers_of(engine: Engine) -> threading.RLock | None:
    if engine.dialect.name != "sqlite":
        return None  # PostgreSQL's advisory lock wakes a waiting writer as soon as it is free
    key = engine.url.render_as_string(hide_password=False)
    with _WRITERS_LOCK:
        return _WRITERS.setdefault(key, threading.RLock())


@contextmanager
def transaction(factory: sessionmaker[Session]) -> Iterator[Session]:
    """A read-write transaction holding the write lock from its start (SQLite ``BEGIN IMMEDIATE``)."""
    writers = _writers_of(engine_of(factory))
    with writers if writers is not None else nullcontext(), factory() as session, session.begin():
        session.connection(execution_options={_BEGIN_OPTION: "IMMEDIATE"})
        yield session


@contextmanager
def transaction_on(connection: Connection) -> Iterator[Session]:
    """:func:`transaction` on a connection its caller keeps open across transactions (a pool checkout and a
    session's own transaction are ~90 us of CPU each time); the session joins the connection's transaction."""
    with (_writers_of(connection.engine) or nullcontext(),
          connection.execution_options(**{_BEGIN_OPTION: "IMMEDIATE"}).begin(),  # the options set in place
          Session(bind=connection, expire_on_commit=False) as session):
        yield session


@contextmanager
def snapshot(factory: sessionmaker[Session]) -> Iterator[Session]:
    """A read-only transaction: one consistent view, no lock that would make a writer wait."""
    with factory() as session, session.begin():
        if session.get_bind().dialect.name == "postgresql":
            session.connection(execution_options={"isolation_level": "REPEATABLE READ"})
        yield session


# -- jobs --------------------------------------------------------------------------------------------------
def create_job(session: Session, *, name: str, spec: dict[str, Any], seed: int, study_id: int | None = None,
               profile_id: int | None = None) -> Job:
    job = Job(name=name, spec=spec, seed=seed, status=WorkStatus.QUEUED, study_id=study_id, profile_id=profile_id)
    session.add(job)
    session.flush()
    return job


def get_row(session: Session, table: Any, row_id: int, what: str) -> Any:
    """The row ``row_id`` of ``table`` (raises NotFound: "no <what> <id>")."""
    row = session.get(table, row_id)
    if row is None:
        raise NotFound(f"no {what} {row_id}")
    return row


def find_named(session: Session, table: Any, name: str, what: str | None = None) -> Any:
    """The row of ``table`` named ``name``: None if there is none, or with ``what`` raises NotFound naming it."""
    row = session.scalar(select(table).where(table.name == name))
    if row is None and what is not None:
        raise NotFound(f"no {what} named {name!r}")
    return row


def get_job(session: Session, *, job_id: int) -> Job:
    return get_row(session, Job, job_id, "job with id")


def find_job(session: Session, *, name: str) -> Job | None:
    return find_named(session, Job, name)


def get_job_by_name(session: Session, *, name: str) -> Job:
    return find_named(session, Job, name, "job")


def set_notes(session: Session, *, job_id: int, notes: str) -> Job:
    job = get_job(session, job_id=job_id)
    job.notes = notes
    return job


def list_jobs(session: Session, *, after: int = 0, limit: int | None = None) -> list[Job]:
    """Jobs with id > after, in id order, at most ``limit``."""
    query = select(Job).where(Job.id > after).order_by(Job.id)
    return list(session.scalars(query if limit is None else query.limit(limit)))


def count_evaluations(session: Session, *, job_id: int) -> int:
    return session.scalar(_COUNT, {"job_id": job_id}) or 0


@dataclass(frozen=True)
class JobForStore:
    """A runner's read of its job to store an evaluation or release it (``run_s``: its runs before this one)."""

    runner_id: str | None
    status: str
    iterations: int
    n_evaluations: int
    started_at: datetime | None
    run_s: float | None


def job_for_store(session: Session, *, job_id: int) -> JobForStore | None:
    """:class:`JobForStore` in one query on the session's connection (the ORM's execution adds ~50 us), the budget
    read out of the stored spec in SQL (decoding the spec at every store was a tenth of the server's work)."""
    row = session.connection().execute(_JOB_FOR_STORE, {"job_id": job_id}).one_or_none()
    return None if row is None else JobForStore(row[0], row[1], int(row[2]), int(row[3] or 0), *row[4:])


def count_and_best(session: Session, *, job_id: int) -> tuple[int, Evaluation | None]:
    """The job's number of stored evaluations and its best (:func:`best_evaluation`), in one query."""
    n, best_completed, best_failed = session.execute(_COUNT_AND_BEST, {"job_id": job_id}).one()
    best_id = best_completed if best_completed is not None else best_failed
    return n or 0, (session.get(Evaluation, best_id) if best_id is not None else None)


def unique_name(session: Session, table: Any, base: str) -> str:
    """``base``, or ``base-2``, ``base-3`` ... : the first name no row of ``table`` has."""
    name, n = base, 1
    while find_named(session, table, name) is not None:
        n += 1
        name = f"{base}-{n}"
    return name


def unique_job_name(session: Session, base: str) -> str:
    return unique_name(session, Job, base)


# -- evaluations -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StoredEvaluation:
    """Where :func:`add_evaluation` put an evaluation: its row id and its index in the job."""

    id: int
    index: int


# The tables, not the ORM classes, and one row, not a list: an INSERT of an ORM class takes the ORM's bulk path, and
# a list the executemany path; together they were ~30 % of a store's CPU (0.98 -> 0.70 ms on SQLite).
_INSERT_EVALUATION = insert(cast(Table, Evaluation.__table__)).returning(Evaluation.__table__.c.id)
_INSERT_TRAJECTORY = insert(cast(Table, Trajectory.__table__))


def add_evaluation(session: Session, *, job_id: int, theta: dict[str, float], J: float, status: str,
                   metrics: dict[str, Any], trigger_points: list[dict[str, float]], wall_ms: float,
                   columns: list[str], trajectory: np.ndarray | PackedTrajectory,
                   seeds: list[dict[str, Any]] | None = None, trajectory_seed: int | None = None,
                   max_trajectories: int | None = None, enqueued: bool = False,
                   index: int | None = None) -> StoredEvaluation:
    """Appends the next evaluation of a job (its index is the count so far, so numbering survives resumes).

    Its trajectory (up to ~100 kB) is kept while the job holds fewer than ``max_trajectories`` of them, and always
    when the evaluation is the job's new best: a long job's storage stays bounded and its best stays watchable.
    ``trajectory`` may come packed already (a :class:`PackedTrajectory`, as the episode's worker sends it):
    compressing takes longer than the rest of the commit, and the write lock is held meanwhile. ``index``: the
    job's number of evaluations, where the caller has just read it in this transaction. Two INSERT statements, not
    the ORM's unit of work: its flush was half of a store's work, and a server stores for every running job."""
    index = count_evaluations(session, job_id=job_id) if index is None else index
    # A job holds at most as many trajectories as evaluations: below the cap there is nothing to count. (Decided
    # before the evaluation's own row exists: it would be the best it is compared with.)
    keep = (max_trajectories is None or index < max_trajectories
            or count_trajectories(session, job_id=job_id) < max_trajectories
            or _beats_best(session, job_id=job_id, J=J, completed=status == EpisodeStatus.COMPLETED))
    connection = session.connection()  # Core statements on the session's connection: the ORM adds nothing here
    evaluation_id = connection.execute(
        _INSERT_EVALUATION,
        {"job_id": job_id, "index": index, "theta": theta, "J": J, "status": status, "metrics": metrics,
         "trigger_points": trigger_points, "wall_ms": wall_ms, "seeds": seeds, "trajectory_seed": trajectory_seed,
         "enqueued": enqueued}).scalar_one()
    if keep:
        packed = trajectory if isinstance(trajectory, PackedTrajectory) else PackedTrajectory.of(trajectory)
        connection.execute(_INSERT_TRAJECTORY, {"evaluation_id": evaluation_id, "columns": list(columns),
                                                "rows": packed.rows, "data": packed.data})
    return StoredEvaluation(evaluation_id, index)


def count_trajectories(session: Session, *, job_id: int) -> int:
    return session.scalar(select(func.count()).select_from(Trajectory).join(Evaluation)
                          .where(Evaluation.job_id == job_id)) or 0


def _beats_best(session: Session, *, job_id: int, J: float, completed: bool) -> bool:
    """Would an evaluation with this J and status become the job's best (best_evaluation's order)?"""
    _, best_completed, best_failed = session.execute(_COUNT_AND_BEST, {"job_id": job_id}).one()
    best_id = best_completed if best_completed is not None else best_failed
    if best_id is None:
        return True
    if completed != (best_completed is not None):
        return completed
    return J < session.execute(select(Evaluation.J).where(Evaluation.id == best_id)).scalar_one()


def evaluations(session: Session, *, job_id: int, after: int = -1, limit: int | None = None) -> list[Evaluation]:
    """Evaluations with index > after, in order."""
    query = (select(Evaluation).where(Evaluation.job_id == job_id, Evaluation.index > after)
             .order_by(Evaluation.index))
    if limit is not None:
        query = query.limit(limit)
    return list(session.scalars(query))


def seconds_per_evaluation(session: Session, *, job_id: int, since: datetime | None = None,
                           window: int = 20) -> float | None:
    """Seconds per evaluation over the job's running time only: the last ``window`` evaluations stored since
    ``since`` (the current run's claim; a pause, a resume or a crash before it does not count), or, with fewer,
    the time from ``since`` to the last of them per evaluation. None before the run's first evaluation."""
    stamps = list(session.scalars(select(Evaluation.created_at).where(Evaluation.job_id == job_id)
                                  .order_by(Evaluation.index.desc()).limit(window)))
    if since is not None:
        start = since.replace(tzinfo=None)
        stamps = [t for t in stamps if t.replace(tzinfo=None) >= start]
    if len(stamps) >= window or (since is None and len(stamps) >= 2):
        return (stamps[0] - stamps[-1]).total_seconds() / (len(stamps) - 1)
    if since is None or not stamps:
        return None
    return (stamps[0].replace(tzinfo=None) - since.replace(tzinfo=None)).total_seconds() / len(stamps)


def get_evaluation(session: Session, *, evaluation_id: int) -> Evaluation:
    evaluation = session.get(Evaluation, evaluation_id)
    if evaluation is None:
        raise NotFound(f"no evaluation with id {evaluation_id}")
    return evaluation


def best_evaluation(session: Session, *, job_id: int) -> Evaluation | None:
    """The job's best (driftlab.core.convergence.best_position's rule, in SQL: the lowest completed J, the earliest
    on a tie); while none has completed, the failure with the lowest J (its penalty: the one that drove furthest),
    so that a job always shows something to watch."""
    return count_and_best(session, job_id=job_id)[1]


def _lowest_j(status_filter) -> Any:
    return (select(Evaluation.id).where(Evaluation.job_id == bindparam("job_id"), status_filter)
            .order_by(Evaluation.J, Evaluation.index).limit(1).scalar_subquery())


# Built once: a dashboard and every script poll these, and building a statement costs more than SQLite's answer.
_COUNT = select(func.count()).select_from(Evaluation).where(Evaluation.job_id == bindparam("job_id"))
_JOB_FOR_STORE = (select(Job.runner_id, Job.status, Job.spec["iterations"].as_integer(), _COUNT.scalar_subquery(),
                         Job.started_at, Job.run_s).where(Job.id == bindparam("job_id")))
_COUNT_AND_BEST = select(func.count(), _lowest_j(Evaluation.status == EpisodeStatus.COMPLETED),
                         _lowest_j(Evaluation.status != EpisodeStatus.COMPLETED)
                         ).select_from(Evaluation).where(Evaluation.job_id == bindparam("job_id"))


def best_summary(best: Evaluation | None) -> dict[str, Any] | None:
    """The best evaluation as a job (and compare) shows it. ``id`` is the evaluation's id, the name every
    evaluation carries in the API (``/api/jobs/{id}/best``, ``/evaluations``)."""
    if best is None:
        return None
    return {"id": best.id, "index": best.index, "theta": best.theta, "J": best.J, "status": best.status,
            "seeds": best.seeds, "trajectory_seed": best.trajectory_seed}


def has_trajectory(session: Session, *, evaluation_id: int) -> bool:
    """Whether the evaluation's trajectory is stored (without loading it)."""
    return session.scalar(select(Trajectory.evaluation_id).where(Trajectory.evaluation_id == evaluation_id)) is not None


def trajectory_array(session: Session, *, evaluation_id: int) -> tuple[list[str], np.ndarray]:
    traj = session.get(Trajectory, evaluation_id)
    if traj is None:
        get_evaluation(session, evaluation_id=evaluation_id)  # no such evaluation: say that instead
        raise NotFound(f"the trajectory of evaluation {evaluation_id} was not kept (its job held "
                       f"DRIFTLAB_MAX_TRAJECTORIES_PER_JOB of them; the best's always are): re-run it with "
                       f"`driftlab episode` from its theta, config and trajectory_seed (an episode is deterministic)")
    return traj.columns, unpack(traj.data, traj.rows, len(traj.columns))
