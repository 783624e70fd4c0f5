"""A robustness study's lease, on a real SQLite file: one runner at a time, a dead runner's study taken over,
a pause seen at the next heartbeat, and a seeds study's status and lifecycle read from its jobs."""

from datetime import timedelta

import pytest

from driftlab.core.tuning import TuningSpec
from driftlab.db import lifecycle, storage, studies
from driftlab.db.models import Study, utcnow


@pytest.fixture
def factory(tmp_path):
    return storage.open_database(f"sqlite:///{tmp_path / 'studies.db'}")


def _robustness(factory):
    with storage.transaction(factory) as session:
        study = studies.create_study(session, name="grid", kind="robustness", spec={})
        studies.add_cells(session, study_id=study.id, cells=[{"plant.mass_scale": 1.0}])
        return study.id


def test_one_runner_holds_a_study_and_a_dead_runners_study_is_taken_over(factory):
    study_id = _robustness(factory)
    with storage.transaction(factory) as session:
        assert studies.next_claimable_study(session) == study_id
        assert studies.claim_study(session, study_id=study_id, runner="a")
    with storage.transaction(factory) as session:
        assert not studies.claim_study(session, study_id=study_id, runner="b")  # a's lease is live
        assert studies.next_claimable_study(session) is None
        with pytest.raises(lifecycle.TransitionError, match="running"):
            studies.delete_study(session, study_id=study_id)
    with storage.transaction(factory) as session:  # a dies: its heartbeat gets old
        session.get(Study, study_id).heartbeat_at = (utcnow() - timedelta(seconds=60)).replace(tzinfo=None)
    with storage.transaction(factory) as session:
        assert studies.next_claimable_study(session) == study_id
        assert studies.claim_study(session, study_id=study_id, runner="b")
    with storage.transaction(factory) as session:
        assert not studies.heartbeat_study(session, study_id=study_id, runner="a")
        studies.release_study(session, study_id=study_id, runner="a", status="finished")  # too late: no effect
        assert session.get(Study, study_id).runner_id == "b"
        studies.pause_study(session, study_id=study_id)
    with storage.transaction(factory) as session:
        assert not studies.heartbeat_study(session, study_id=study_id, runner="b")  # b stops
        studies.release_study(session, study_id=study_id, runner="b", status="finished")
        study = session.get(Study, study_id)
        assert study.status == "paused" and study.runner_id is None


def test_a_seeds_studys_status_and_lifecycle_are_its_jobs(factory):
    with storage.transaction(factory) as session:
        study = studies.create_study(session, name="s", kind="seeds", spec={}, status="jobs")
        ids = [storage.create_job(session, name=f"s-{seed}", spec=TuningSpec().to_dict(), seed=seed,
                                  study_id=study.id).id for seed in (0, 1)]
        assert studies.study_status(session, study) == "queued"
        studies.pause_study(session, study_id=study.id)
        assert studies.study_status(session, study) == "paused"
        lifecycle.extend(session, job_id=ids[0], iterations=0)  # paused, nothing to do: finished
        studies.resume_study(session, study_id=study.id)
        assert [storage.get_job(session, job_id=i).status for i in ids] == ["finished", "queued"]
        with pytest.raises(lifecycle.TransitionError, match="no paused or failed job"):
            studies.resume_study(session, study_id=study.id)
        lifecycle.extend(session, job_id=ids[1], iterations=0)
        assert studies.study_status(session, study) == "finished"
    with storage.transaction(factory) as session:
        studies.delete_study(session, study_id=study.id)
    with storage.transaction(factory) as session:
        assert storage.list_jobs(session) == [] and studies.list_studies(session) == []


def _seeds_study(factory, seeds=(0, 1)):
    with storage.transaction(factory) as session:
        study = studies.create_study(session, name="s", kind="seeds", spec={}, status="jobs")
        ids = [storage.create_job(session, name=f"s-{seed}", spec=TuningSpec().to_dict(), seed=seed,
                                  study_id=study.id).id for seed in seeds]
        return study.id, ids


def test_a_seeds_studys_job_is_deleted_only_with_its_study(factory):
    study_id, ids = _seeds_study(factory)
    with storage.transaction(factory) as session, pytest.raises(lifecycle.TransitionError,
                                                                   match=r"seeds study 's' \(id 1\)"):
        lifecycle.delete_job(session, job_id=ids[0])
    with storage.transaction(factory) as session:
        assert [j.id for j in studies.study_jobs(session, study_id=study_id)] == ids  # nothing changed
        studies.delete_study(session, study_id=study_id)
    with storage.transaction(factory) as session:
        assert storage.list_jobs(session) == []


def test_a_held_seeds_study_is_run_by_its_holder_only_until_the_holder_dies(factory):
    study_id, ids = _seeds_study(factory)
    with storage.transaction(factory) as session:
        studies.hold_seeds_study(session, study_id=study_id, runner="cli")
    with storage.transaction(factory) as session:
        assert lifecycle.claimable(session, limit=1) == []  # a server's runner leaves the study's jobs alone
        with pytest.raises(lifecycle.LeaseHeld, match="belongs to study 's'"):
            lifecycle.claim(session, job_id=ids[0], runner="server")
        with pytest.raises(lifecycle.LeaseHeld, match="being run by cli"):
            studies.hold_seeds_study(session, study_id=study_id, runner="another-cli")
    with storage.transaction(factory) as session:
        lifecycle.claim(session, job_id=ids[0], runner="cli")
    with storage.transaction(factory) as session:  # the job's heartbeat renews the study's hold
        session.get(Study, study_id).heartbeat_at = (utcnow() - timedelta(seconds=10)).replace(tzinfo=None)
    with storage.transaction(factory) as session:
        assert lifecycle.heartbeat(session, job_id=ids[0], runner="cli")
        age = utcnow().replace(tzinfo=None) - session.get(Study, study_id).heartbeat_at
        assert age < timedelta(seconds=5)
    with storage.transaction(factory) as session:  # the holder dies: its hold and its job's lease get old
        old = (utcnow() - timedelta(seconds=60)).replace(tzinfo=None)
        session.get(Study, study_id).heartbeat_at = old
        storage.get_job(session, job_id=ids[0]).heartbeat_at = old
    with storage.transaction(factory) as session:
        assert lifecycle.claimable(session, limit=1) == [ids[0]]
        lifecycle.claim(session, job_id=ids[1], runner="server")
    with storage.transaction(factory) as session:
        studies.let_go_seeds_study(session, study_id=study_id, runner="cli")
        assert session.get(Study, study_id).runner_id is None
