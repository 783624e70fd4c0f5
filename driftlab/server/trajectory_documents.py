"""GET /api/evaluations/{id}/trajectory, encoded once per evaluation.

A stored trajectory never changes, and the same few are read again and again (the best of a running job, which every
dashboard tab and rewatch asks for): decompressing one and writing its rows as JSON or CSV took 7-25 ms of the one
server process, which every other request then waits behind. So the encoded documents of the most recently read
trajectories are kept, up to MAX_BYTES of text. Evaluation ids are never reused; a document is found again only
under its job's current name (the metadata carries it) and while its trajectory is still stored (past
DRIFTLAB_MAX_TRAJECTORIES_PER_JOB a job stores new evaluations without one).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Literal

from sqlalchemy.orm import Session

from driftlab.core.track import FigureEight
from driftlab.db import storage
from driftlab.reports.export import trajectory_csv, trajectory_json, with_lap_column
from driftlab.server.serialize import trajectory_metadata

MAX_BYTES = 64 * 2**20  # ~100 JSON documents of 30 s episodes

Format = Literal["csv", "json"]


class TrajectoryDocuments:
    """The trajectory documents GET /trajectory serves, the recently read ones kept encoded."""

    def __init__(self, max_bytes: int = MAX_BYTES) -> None:
        self.max_bytes = max_bytes
        self._documents: OrderedDict[tuple, str] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def document(self, session: Session, *, evaluation_id: int, format: Format) -> str:  # noqa: A002
        """The evaluation's trajectory as a JSON document or a CSV file with its metadata (raises
        storage.NotFound for no such evaluation or a trajectory not kept)."""
        evaluation = storage.get_evaluation(session, evaluation_id=evaluation_id)
        if not storage.has_trajectory(session, evaluation_id=evaluation_id):
            storage.trajectory_array(session, evaluation_id=evaluation_id)  # raises NotFound, saying why
        job = storage.get_job(session, job_id=evaluation.job_id)
        key = (evaluation_id, format, job.name)
        with self._lock:
            if key in self._documents:
                self._documents.move_to_end(key)
                return self._documents[key]
        columns, data = storage.trajectory_array(session, evaluation_id=evaluation_id)
        track = FigureEight.of_scenario(job.spec.get("config", {}).get("scenario", {}))
        columns, data = with_lap_column(columns, data, track)
        metadata = trajectory_metadata(evaluation, job)
        text = trajectory_json(columns, data, metadata) if format == "json" else trajectory_csv(columns, data)
        self._keep(key, text)
        return text

    def _keep(self, key: tuple, text: str) -> None:
        with self._lock:
            if key in self._documents or len(text) > self.max_bytes:
                return
            self._documents[key] = text
            self._bytes += len(text)
            while self._bytes > self.max_bytes:
                _, dropped = self._documents.popitem(last=False)
                self._bytes -= len(dropped)
