"""The trajectory download cache: what encoding the stored trajectory gives, again from the cache; a renamed job's
metadata, a dropped trajectory and a deleted job are never answered from it."""

import json

import numpy as np
import pytest
from sqlalchemy import delete

from driftlab.core.loop_state import COLUMNS
from driftlab.core.track import FigureEight
from driftlab.db import lifecycle, storage
from driftlab.db.models import Trajectory
from driftlab.reports.export import trajectory_csv, trajectory_json, with_lap_column
from driftlab.server.serialize import trajectory_metadata
from driftlab.server.trajectory_documents import TrajectoryDocuments


def _job_with_evaluations(factory, name="j", n=3):
    rows = np.random.default_rng(5).normal(size=(40, len(COLUMNS)))
    rows[:, COLUMNS.index("t_s")] = np.arange(40) * 0.05
    with storage.transaction(factory) as session:
        job = storage.create_job(session, name=name, spec={"iterations": 50}, seed=0)
        ids = [storage.add_evaluation(session, job_id=job.id, theta={"k": 0.01 * i}, J=float(i), status="completed",
                                      metrics={"mean_abs_e_m": 0.1}, trigger_points=[], wall_ms=1.0,
                                      columns=list(COLUMNS), trajectory=rows + i).id for i in range(n)]
    return job.id, ids


def _encoded(factory, evaluation_id, fmt):
    with storage.snapshot(factory) as session:
        columns, data = storage.trajectory_array(session, evaluation_id=evaluation_id)
        e = storage.get_evaluation(session, evaluation_id=evaluation_id)
        job = storage.get_job(session, job_id=e.job_id)
        columns, data = with_lap_column(columns, data, FigureEight.of_scenario({}))
        return (trajectory_json(columns, data, trajectory_metadata(e, job)) if fmt == "json"
                else trajectory_csv(columns, data))


def _document(factory, documents, evaluation_id, fmt):
    with storage.snapshot(factory) as session:
        return documents.document(session, evaluation_id=evaluation_id, format=fmt)


@pytest.fixture
def factory(tmp_path):
    return storage.open_database(f"sqlite:///{tmp_path / 'docs.db'}")


def test_documents_are_what_encoding_the_stored_trajectory_gives_read_again_and_again(factory):
    _, ids = _job_with_evaluations(factory)
    documents = TrajectoryDocuments()
    for _ in range(2):  # the second round comes from the cache
        for evaluation_id in ids:
            for fmt in ("json", "csv"):
                assert _document(factory, documents, evaluation_id, fmt) == _encoded(factory, evaluation_id, fmt)


def test_a_renamed_job_gets_its_new_name_in_the_metadata(factory):
    job_id, ids = _job_with_evaluations(factory, name="before")
    documents = TrajectoryDocuments()
    assert json.loads(_document(factory, documents, ids[0], "json"))["metadata"]["job_name"] == "before"
    with storage.transaction(factory) as session:
        storage.get_job(session, job_id=job_id).name = "after"
    assert json.loads(_document(factory, documents, ids[0], "json"))["metadata"]["job_name"] == "after"


def test_plain_pandas_read_csv_of_a_download_gives_the_trajectorys_columns(factory, tmp_path):
    """The first line a person types: ``pd.read_csv("evaluation-N.csv")``, no option, gives one column per
    trajectory column with its numbers (integers for the phase and lap), the rows the JSON download has."""
    import pandas as pd

    _, ids = _job_with_evaluations(factory)
    documents = TrajectoryDocuments()
    path = tmp_path / f"evaluation-{ids[0]}.csv"
    path.write_text(_document(factory, documents, ids[0], "csv"))
    frame = pd.read_csv(path)
    document = json.loads(_document(factory, documents, ids[0], "json"))
    assert list(frame.columns) == document["columns"] == [*COLUMNS, "lap"]
    assert frame.to_numpy().tolist() == document["rows"]
    assert frame["phase"].dtype.kind == "i" and frame["lap"].dtype.kind == "i" and frame["t_s"].dtype.kind == "f"


def test_a_dropped_trajectory_or_a_deleted_job_is_not_found_though_it_was_read_before(factory):
    job_id, ids = _job_with_evaluations(factory)
    documents = TrajectoryDocuments()
    for evaluation_id in ids:
        _document(factory, documents, evaluation_id, "json")
    with storage.transaction(factory) as session:
        session.execute(delete(Trajectory).where(Trajectory.evaluation_id == ids[0]))
    with pytest.raises(storage.NotFound, match="was not kept"):
        _document(factory, documents, ids[0], "json")
    with storage.transaction(factory) as session:
        lifecycle.delete_job(session, job_id=job_id)
    with pytest.raises(storage.NotFound, match=f"no evaluation with id {ids[1]}"):
        _document(factory, documents, ids[1], "json")


def test_the_cache_keeps_to_its_size(factory):
    _, ids = _job_with_evaluations(factory, n=6)
    one = len(_encoded(factory, ids[0], "json"))
    documents = TrajectoryDocuments(max_bytes=int(2.5 * one))
    for evaluation_id in ids:
        assert _document(factory, documents, evaluation_id, "json") == _encoded(factory, evaluation_id, "json")
    assert documents._bytes <= documents.max_bytes and len(documents._documents) == 2
