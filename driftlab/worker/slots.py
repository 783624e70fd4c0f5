"""The executor's capacity (episodes it runs at once: the local pool's processes, the Dask cluster's threads)
shared among the jobs that run on it at the same time.

Each job keeps at most its fair share of episodes in flight (the capacity split evenly among the jobs running now,
the remainder to those that joined first), and all of them together never more than the capacity: the workers are
filled, never oversubscribed. A job that finishes (or pauses) leaves and frees its share for the others; a job that
joins takes its share as the others' episodes come back (nothing in flight is cancelled).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable
from typing import Any, Protocol

# How often a capacity that follows the executor (a Dask cluster's worker threads) is read again.
CAPACITY_READ_EVERY_S = 1.0


def capacity_of(executor: Any, workers_given: int | None, workers: int) -> int | Callable[[], int]:
    """The slots' capacity: the worker count given, fixed; else, where the executor has one, its capacity as it is
    now (a Dask cluster that grows takes more episodes at once, one that shrinks fewer), else ``workers``."""
    follow = getattr(executor, "capacity", None)
    return follow if workers_given is None and callable(follow) else workers


class Wake(Protocol):
    """What a job waits on (a threading.Event, or what sets several)."""

    def set(self) -> None: ...


class EpisodeSlots:
    def __init__(self, capacity: int | Callable[[], int]) -> None:
        """``capacity``: episodes the executor runs at once, or a function that says how many now (read at most
        every CAPACITY_READ_EVERY_S)."""
        self._capacity_now = capacity if callable(capacity) else None
        self._capacity = max(int(capacity() if callable(capacity) else capacity), 1)
        self._read_at = time.monotonic()
        self._lock = threading.Lock()
        self._held: dict[Hashable, int] = {}  # episodes in flight per job, in the order the jobs joined
        self._wakes: dict[Hashable, Wake] = {}
        self._in_flight = 0
        self.peak = 0  # the most episodes in flight at once so far

    @property
    def capacity(self) -> int:
        """Episodes the executor runs at once (now, for a capacity that follows the executor)."""
        if self._capacity_now is not None and time.monotonic() - self._read_at >= CAPACITY_READ_EVERY_S:
            self._read_at = time.monotonic()
            before, self._capacity = self._capacity, max(int(self._capacity_now()), 1)
            if self._capacity > before:  # more room: whoever waits for a slot may take one now
                self._wake_all()
        return self._capacity

    def join(self, owner: Hashable, wake: Wake | None = None) -> None:
        """``owner`` (one running job) takes part; ``wake`` is set whenever a slot it may use becomes free."""
        with self._lock:
            self._held.setdefault(owner, 0)
            if wake is not None:
                self._wakes[owner] = wake

    def leave(self, owner: Hashable) -> None:
        """The job stops: whatever it still counted as in flight is freed, and its share goes to the others."""
        with self._lock:
            self._in_flight -= self._held.pop(owner, 0)
            self._wakes.pop(owner, None)
            self._wake_all()

    def _share(self, owner: Hashable) -> int:
        n = len(self._held)
        base, extra = divmod(self.capacity, max(n, 1))
        rank = list(self._held).index(owner)
        return max(base + (rank < extra), 1)

    def share(self, owner: Hashable) -> int:
        """How many episodes ``owner`` may keep in flight now."""
        with self._lock:
            return self._share(owner)

    def _room(self, owner: Hashable) -> bool:
        return self._held[owner] < self._share(owner) and self._in_flight < self.capacity

    def try_take(self, owner: Hashable) -> bool:
        """Count one more episode of ``owner`` in flight if its share and the capacity allow it."""
        with self._lock:
            if not self._room(owner):
                return False
            self._held[owner] += 1
            self._in_flight += 1
            self.peak = max(self.peak, self._in_flight)
            return True

    def give_back(self, owner: Hashable) -> None:
        """One episode of ``owner`` came back."""
        with self._lock:
            if self._held.get(owner, 0) > 0:
                full = self._in_flight >= self.capacity
                self._held[owner] -= 1
                self._in_flight -= 1
                if full:  # a job held back by the capacity (not by its own share) may go on
                    self._wake_those_with_room(but=owner)

    def _wake_all(self) -> None:
        for wake in list(self._wakes.values()):  # a copy: the capacity is also read without the lock (JobPool.free)
            wake.set()

    def _wake_those_with_room(self, but: Hashable) -> None:
        """Wakes the jobs that could start an episode now, other than ``but`` (the job giving a slot back, awake
        already). While every job is at its share, most of the time under load, that is none: waking every job at
        every episode's return turned each job's loop ~28 times an evaluation at 8 jobs on 16 workers."""
        for owner, wake in self._wakes.items():
            if owner != but and self._room(owner):
                wake.set()

    def owners_in_flight(self) -> tuple[Hashable, ...]:
        """The owners with at least one episode in flight now, in the order they joined."""
        with self._lock:
            return tuple(owner for owner, held in self._held.items() if held > 0)

    @property
    def in_flight(self) -> int:
        with self._lock:
            return self._in_flight
