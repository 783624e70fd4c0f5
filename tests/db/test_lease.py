"""A job's lease on a real SQLite file: a runner's lease holds for LEASE_TIMEOUT_S after its last heartbeat and no
longer (the end-to-end kill -9 tests start their next server with the dead server's lease already that old)."""

from datetime import timedelta

import pytest

from driftlab.core.tuning import TuningSpec
from driftlab.db import lifecycle, storage
from driftlab.db.lease import LEASE_TIMEOUT_S
from driftlab.db.models import Job, utcnow


@pytest.fixture
def factory(tmp_path):
    return storage.open_database(f"sqlite:///{tmp_path / 'lease.db'}")


def _heartbeat_ago(factory, job_id, seconds):
    with storage.transaction(factory) as session:
        session.get(Job, job_id).heartbeat_at = (utcnow() - timedelta(seconds=seconds)).replace(tzinfo=None)


@pytest.mark.parametrize("age_s", [0.0, LEASE_TIMEOUT_S - 2.0])
def test_a_live_runners_job_is_neither_claimable_nor_taken(factory, age_s):
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="held", spec=TuningSpec(iterations=3).to_dict(), seed=0).id
        lifecycle.claim(session, job_id=job_id, runner="a")
    _heartbeat_ago(factory, job_id, age_s)
    with storage.transaction(factory) as session:
        assert lifecycle.claimable(session, limit=1) == []
        with pytest.raises(lifecycle.LeaseHeld):
            lifecycle.claim(session, job_id=job_id, runner="b")


def test_a_dead_runners_job_is_taken_over_once_its_heartbeat_is_older_than_the_timeout(factory):
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="orphan", spec=TuningSpec(iterations=3).to_dict(), seed=0).id
        lifecycle.claim(session, job_id=job_id, runner="a")
    _heartbeat_ago(factory, job_id, LEASE_TIMEOUT_S + 1.0)
    with storage.transaction(factory) as session:
        assert lifecycle.claimable(session, limit=1) == [job_id]
        lifecycle.claim(session, job_id=job_id, runner="b")
        assert session.get(Job, job_id).runner_id == "b"
    with storage.transaction(factory) as session:
        assert not lifecycle.heartbeat(session, job_id=job_id, runner="a")  # the dead runner, back, must stop
        assert lifecycle.heartbeat(session, job_id=job_id, runner="b")


def test_a_runner_claims_what_it_has_room_for_oldest_first_in_one_look(factory):
    with storage.transaction(factory) as session:
        ids = [storage.create_job(session, name=f"j{i}", spec=TuningSpec(iterations=3).to_dict(), seed=i).id
               for i in range(4)]
        lifecycle.claim(session, job_id=ids[0], runner="a")
    _heartbeat_ago(factory, ids[0], LEASE_TIMEOUT_S + 1.0)  # its runner died: claimable again, and the oldest
    with storage.transaction(factory) as session:
        assert lifecycle.claimable(session, limit=3) == ids[:3]
        lifecycle.claim(session, job_id=ids[1], runner="b")
        assert lifecycle.claimable(session, limit=9) == [ids[0], ids[2], ids[3]]
