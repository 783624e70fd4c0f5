"""GET /api/jobs/{id}/evaluations as JSON, serialized once per evaluation.

A stored evaluation never changes, and a dashboard polls the whole list of a job while it runs: a 500-evaluation
job is ~750 kB of JSON, ~45 ms of loading rows and encoding them in the one server process, which every other
request then waits behind (26 readers while a job runs on 2 workers: reads p99 1.1 s). So each job's evaluations
are kept as their JSON text, in index order, and a read loads only the rows stored since; the page is a slice of
those texts joined. Bounded: the most recently read jobs only, and none larger than MAX_ROWS.
"""

from __future__ import annotations

import json
import threading
from bisect import bisect_right
from collections import OrderedDict
from dataclasses import dataclass, field

from sqlalchemy.orm import Session

from driftlab.db import storage
from driftlab.server.serialize import evaluation_dict

MAX_JOBS = 8
MAX_ROWS = 20_000  # ~30 MB of text: a larger job is served uncached


@dataclass
class _JobRows:
    created_at: str  # a job id reused after a delete is another job
    indexes: list[int] = field(default_factory=list)
    texts: list[str] = field(default_factory=list)


class EvaluationPages:
    """The JSON text of each job's stored evaluations, for the pages GET /evaluations serves."""

    def __init__(self) -> None:
        self._jobs: OrderedDict[int, _JobRows] = OrderedDict()
        self._lock = threading.Lock()

    def page(self, session: Session, *, job_id: int, after: int, limit: int) -> str:
        """The JSON array of the job's evaluations with index > after, at most ``limit`` (raises
        storage.NotFound)."""
        job = storage.get_job(session, job_id=job_id)
        created_at = job.created_at.isoformat()
        with self._lock:
            rows = self._jobs.get(job_id)
            if rows is None or rows.created_at != created_at:
                rows = _JobRows(created_at)
            last = rows.indexes[-1] if rows.indexes else -1
        if storage.count_evaluations(session, job_id=job_id) > MAX_ROWS:
            with self._lock:
                self._jobs.pop(job_id, None)
            chosen = storage.evaluations(session, job_id=job_id, after=after, limit=limit)
            return json.dumps([evaluation_dict(e) for e in chosen])
        new = storage.evaluations(session, job_id=job_id, after=last)
        texts = [json.dumps(evaluation_dict(e)) for e in new]
        with self._lock:
            current = self._jobs.get(job_id)
            if current is None or current.created_at != created_at or len(current.indexes) < len(rows.indexes):
                current = rows
            # Another read may have appended meanwhile: add only what is still newer.
            top = current.indexes[-1] if current.indexes else -1
            for e, text in zip(new, texts, strict=True):
                if e.index > top:
                    current.indexes.append(e.index)
                    current.texts.append(text)
            self._jobs[job_id] = current
            self._jobs.move_to_end(job_id)
            while len(self._jobs) > MAX_JOBS:
                self._jobs.popitem(last=False)
            start = bisect_right(current.indexes, after)
            return "[" + ", ".join(current.texts[start:start + limit]) + "]"  # as json.dumps of the list
