"""A cap on the reads that cost a server CPU seconds (a job's search space, episode recordings and replays; a
trajectory download is not one): at most ``DRIFTLAB_MAX_HEAVY_READS`` run at once. One more waits for a slot on the
event loop, holding no thread, for up to ``WAIT_S``, then is answered with 503 and a Retry-After. Queued in the thread
pool instead, they held every thread of the server's pool (45 tabs on the search space of a 500-evaluation job: the
health check's p99 30 s), and everything else waited behind them.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import AsyncIterator

from fastapi import HTTPException, Request

RETRY_AFTER_S = 2
WAIT_S = 5.0  # a download in a busy minute waits rather than fails
_POLL_S = 0.05


class HeavyReads:
    """The heavy reads in flight, counted under a lock (the routes run in the thread pool, the waits on the loop)."""

    def __init__(self, limit: int, wait_s: float = WAIT_S) -> None:
        self.limit = limit
        self.wait_s = wait_s
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

    async def enter(self) -> bool:
        """A slot within ``wait_s``, polled on the event loop (False: none came free)."""
        deadline = time.monotonic() + self.wait_s
        while not self.try_enter():
            if time.monotonic() >= deadline:
                return False
            await asyncio.sleep(_POLL_S)
        return True


async def heavy_read(request: Request) -> AsyncIterator[None]:
    """A route dependency: a slot for the request's duration, or 503 with Retry-After when none came free."""
    reads: HeavyReads = request.app.state.heavy_reads
    if not await reads.enter():
        raise HTTPException(503, f"busy: {reads.limit} heavy reads (search spaces, recordings) are "
                                 f"running (DRIFTLAB_MAX_HEAVY_READS); try again in {RETRY_AFTER_S} s",
                            headers={"Retry-After": str(RETRY_AFTER_S)})
    try:
        yield
    finally:
        reads.leave()
