"""A check and the write it guards see the same database: two writers take turns, on a real SQLite file and on a
real PostgreSQL server."""

import threading
import time

import numpy as np
import pytest

from driftlab.db import lifecycle, storage
from driftlab.db.models import Job


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.e2e)])
def factory(request, tmp_path):
    url = (f"sqlite:///{tmp_path / 'driftlab.db'}" if request.param == "sqlite"
           else request.getfixturevalue("postgres").new_database())
    factory = storage.open_database(url)
    with storage.transaction(factory) as session:
        storage.create_job(session, name="j", spec={"iterations": 5}, seed=0)
    return factory


def _store_slowly(factory, started: threading.Event, budget_seen: list[int]) -> None:
    """A runner's store: read the budget, then (a moment later) append an evaluation, in one transaction."""
    with storage.transaction(factory) as session:
        budget_seen.append(int(session.get(Job, 1).spec["iterations"]))
        started.set()
        time.sleep(0.4)
        storage.add_evaluation(session, job_id=1, theta={"k": 0.1}, J=1.0, status="completed", metrics={},
                               trigger_points=[], wall_ms=1.0, columns=["t"], trajectory=np.zeros((2, 1)))


def test_a_budget_cannot_be_lowered_under_an_evaluation_being_stored(factory):
    started, budget_seen = threading.Event(), []
    runner = threading.Thread(target=_store_slowly, args=(factory, started, budget_seen))
    runner.start()
    started.wait(5)
    with storage.snapshot(factory) as session:  # what a client saw: nothing stored yet
        assert storage.count_evaluations(session, job_id=1) == 0
    # The client lowers the budget to what it saw. Without the write lock taken at BEGIN, this would count 0,
    # commit, and leave a job with budget 0 and one evaluation (write skew); now it waits and counts 1.
    with pytest.raises(lifecycle.TransitionError, match="at least the 1 evaluations"):
        with storage.transaction(factory) as session:
            lifecycle.extend(session, job_id=1, iterations=0)
    runner.join()
    assert budget_seen == [5]
    with storage.snapshot(factory) as session:
        assert session.get(Job, 1).spec["iterations"] == 5 and storage.count_evaluations(session, job_id=1) == 1


def test_a_snapshot_reads_while_a_writer_holds_the_lock(factory):
    started, budget_seen = threading.Event(), []
    runner = threading.Thread(target=_store_slowly, args=(factory, started, budget_seen))
    runner.start()
    started.wait(5)
    t0 = time.perf_counter()
    with storage.snapshot(factory) as session:
        assert storage.count_evaluations(session, job_id=1) == 0
    waited_s = time.perf_counter() - t0
    runner.join()
    assert waited_s < 0.3  # the writer sleeps 0.4 s holding the lock: a reader that waited would see its row


def test_two_writers_never_store_the_same_index(factory):
    def store():
        for _ in range(20):
            with storage.transaction(factory) as session:
                storage.add_evaluation(session, job_id=1, theta={"k": 0.1}, J=1.0, status="completed", metrics={},
                                       trigger_points=[], wall_ms=1.0, columns=["t"], trajectory=np.zeros((2, 1)))

    writers = [threading.Thread(target=store) for _ in range(2)]
    for w in writers:
        w.start()
    for w in writers:
        w.join()
    with storage.snapshot(factory) as session:
        assert sorted(e.index for e in storage.evaluations(session, job_id=1)) == list(range(40))


def test_a_budget_raised_after_the_runners_last_look_queues_the_job_it_would_finish(factory):
    with storage.transaction(factory) as session:
        lifecycle.claim(session, job_id=1, runner="r")
    for _ in range(2):
        with storage.transaction(factory) as session:
            storage.add_evaluation(session, job_id=1, theta={"k": 0.1}, J=1.0, status="completed", metrics={},
                                   trigger_points=[], wall_ms=1.0, columns=["t"], trajectory=np.zeros((2, 1)))
    with storage.transaction(factory) as session:  # the runner read 2 as its budget; a PATCH raises it to 5
        lifecycle.extend(session, job_id=1, iterations=5)
    with storage.transaction(factory) as session:
        lifecycle.release(session, job_id=1, runner="r", status=lifecycle.WorkStatus.FINISHED)
    with storage.snapshot(factory) as session:
        job = session.get(Job, 1)
        assert (job.status, job.runner_id) == ("queued", None)
    with storage.transaction(factory) as session:  # a budget that is spent finishes it
        lifecycle.claim(session, job_id=1, runner="r2")
        lifecycle.extend(session, job_id=1, iterations=2)
        lifecycle.release(session, job_id=1, runner="r2", status=lifecycle.WorkStatus.FINISHED)
    with storage.snapshot(factory) as session:
        assert session.get(Job, 1).status == "finished"


def _writes_behind_a_held_writer(factory, writes: dict) -> dict:
    """Each of ``writes`` (name -> fn(session)) handed to the group committer on a thread of its own while its writer
    thread is held by a first write; their results (or exceptions) by name."""
    from driftlab.db import group_commit

    release, results = threading.Event(), {}

    def call(name, fn):
        try:
            results[name] = group_commit.write(factory, fn)
        except ValueError as exc:
            results[name] = exc

    first = threading.Thread(target=call, args=("first", lambda session: release.wait(5)))
    first.start()
    time.sleep(0.2)
    threads = [threading.Thread(target=call, args=item) for item in writes.items()]
    for thread in threads:
        thread.start()
    time.sleep(0.2)
    release.set()
    for thread in [first, *threads]:
        thread.join(10)
    return results


def _append(session, j):
    return storage.add_evaluation(session, job_id=1, theta={"k": j}, J=j, status="completed", metrics={},
                                  trigger_points=[], wall_ms=1.0, columns=["t"], trajectory=np.zeros((2, 1))).index


def test_writes_waiting_together_commit_together_and_one_writes_error_is_its_callers_alone(factory):
    from sqlalchemy import event

    commits = []
    engine = storage.engine_of(factory)
    event.listen(engine, "commit", lambda connection: commits.append(1))
    together = _writes_behind_a_held_writer(factory, {"a": lambda s: _append(s, 1.0), "b": lambda s: _append(s, 2.0)})
    assert sorted([together["a"], together["b"]]) == [0, 1] and len(commits) == 2  # the held write's, then one

    def broken(session):
        _append(session, 9.0)  # written, then rolled back with its error
        raise ValueError("this write's own error")

    apart = _writes_behind_a_held_writer(factory, {"bad": broken, "c": lambda s: _append(s, 3.0)})
    assert isinstance(apart["bad"], ValueError) and apart["c"] == 2
    with storage.snapshot(factory) as session:
        assert sorted(e.J for e in storage.evaluations(session, job_id=1)) == [1.0, 2.0, 3.0]
