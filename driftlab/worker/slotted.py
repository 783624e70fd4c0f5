"""The one loop that runs a piece of leased work's episodes (a rescore's seeds, a calibration's batches, a robustness
study's cells) on the runner's executor: never more in flight than its share of the episode slots
(driftlab.worker.slots), each result handed over as it comes back, and the lease looked after between results.

Each kind supplies only what it does with a result (store a sample, a cell, a score) and what it checks between
them (the lease, a stop request); submit, wait, give back and drop-on-stop are this loop's.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable, Iterable
from concurrent.futures import Future
from typing import Any

from driftlab.db.lease import HEARTBEAT_S
from driftlab.worker.executors import EpisodeExecutor, EpisodeOutcome
from driftlab.worker.slots import EpisodeSlots

Task = tuple[dict[str, float], dict[str, Any], int]  # (theta, config document, seed): one episode


class SlottedEpisodes:
    """``owner``'s part of the shared slots while the ``with`` block runs (joined on entry, left on exit: its share
    goes back to the others, whatever it still had in flight is freed). :meth:`run` may be called from several
    threads at once (a calibration's candidate searches), their episodes sharing the owner's part: each run waits on
    an event of its own, as one shared event cleared by one run would leave another asleep until its heartbeat."""

    def __init__(self, executor: EpisodeExecutor, slots: EpisodeSlots, owner: Hashable) -> None:
        self.executor, self.slots, self.owner = executor, slots, owner
        self.waiting: set[threading.Event] = set()  # the event of each run in progress

    def __enter__(self) -> SlottedEpisodes:
        self.slots.join(self.owner, self)
        return self

    def set(self) -> None:
        """Wakes every run in progress: a slot it may use became free (EpisodeSlots' wake)."""
        for event in list(self.waiting):
            event.set()

    def __exit__(self, *exc_info: object) -> None:
        self.slots.leave(self.owner)

    def run(self, tasks: Iterable[Task], on_result: Callable[[int, EpisodeOutcome], None],
            go_on: Callable[[], bool]) -> bool:
        """Runs ``tasks`` in order, calling ``on_result(index, outcome)`` as each comes back (in the order they come
        back) and ``go_on()`` after each wait, at least every HEARTBEAT_S: the place to renew a lease. ``go_on()``
        False (or an exception from either) stops the run, and what is in flight is dropped: whoever runs the work
        next runs those episodes again. Returns whether every task came back."""
        waiting = list(enumerate(tasks))
        waiting.reverse()  # popped from the end: submitted in the order given
        in_flight: dict[Future[EpisodeOutcome], int] = {}
        wake = threading.Event()
        self.waiting.add(wake)
        try:
            while waiting or in_flight:
                while waiting and self.slots.try_take(self.owner):
                    index, (theta, document, seed) = waiting.pop()
                    future = self.executor.submit(theta, document, seed)
                    future.add_done_callback(lambda _: wake.set())
                    in_flight[future] = index
                wake.wait(timeout=HEARTBEAT_S)
                wake.clear()
                for future in [f for f in in_flight if f.done()]:
                    index = in_flight.pop(future)
                    self.slots.give_back(self.owner)
                    self.set()  # this owner's runs in other threads may take the slot (EpisodeSlots wakes others)
                    on_result(index, future.result())
                if not go_on():
                    return False
            return True
        finally:
            self.waiting.discard(wake)
            for future in in_flight:
                future.cancel()


class LeaseKept:
    """A ``go_on`` for :meth:`SlottedEpisodes.run`: go on while the runner still holds the work (``renew()``, one
    transaction that renews the lease and says whether it was still held, at most every HEARTBEAT_S) and is not
    stopping. ``held`` may also be set False by what stores a result (the lease was gone when it stored)."""

    def __init__(self, renew: Callable[[], bool], should_stop: Callable[[], bool]) -> None:
        self.renew, self.should_stop = renew, should_stop
        self.held, self.last_beat = True, time.monotonic()

    def __call__(self) -> bool:
        if self.held and time.monotonic() - self.last_beat >= HEARTBEAT_S:
            self.held = self.renew()
            self.last_beat = time.monotonic()
        return self.held and not self.should_stop()
