"""A cap on the reads that cost a server CPU seconds (a job's search space, episode recordings, trajectory
downloads): at most ``DRIFTLAB_MAX_HEAVY_READS`` run at once; one more is answered at once with 503 and a
Retry-After instead of queueing. Queued, they held every thread of the server's pool (45 tabs on the search space
of a 500-evaluation job: the health check's p99 30 s), and everything else waited behind them.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator

from fastapi import HTTPException, Request

RETRY_AFTER_S = 2


class HeavyReads:
    """A non-blocking counter of the heavy reads in flight."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._in_flight = 0
        self._lock = threading.Lock()

    def try_enter(self) -> bool:
        with self._lock:
            if self._in_flight >= self.limit:
                return False
            self._in_flight += 1
            return True

    def leave(self) -> None:
        with self._lock:
            self._in_flight -= 1


async def heavy_read(request: Request) -> Iterator[None]:
    """A route dependency: a slot for the request's duration, or 503 with Retry-After when none is free."""
    reads: HeavyReads = request.app.state.heavy_reads
    if not reads.try_enter():
        raise HTTPException(503, f"busy: {reads.limit} heavy reads (search spaces, recordings, trajectories) are "
                                 f"running (DRIFTLAB_MAX_HEAVY_READS); try again in {RETRY_AFTER_S} s",
                            headers={"Retry-After": str(RETRY_AFTER_S)})
    try:
        yield
    finally:
        reads.leave()
